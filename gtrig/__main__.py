from gtrig.cli.main import main

main()
