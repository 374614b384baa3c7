"""gtrig: ground-truth robot trajectories from an instrumented room.

Layers, one way only: :mod:`gtrig.geometry` and the stage subpackages (``survey``, ``calib``,
``markers``, ``vision``, ``laser``, ``fusion``, ``evaluate``) are pure NumPy/SciPy/OpenCV;
:mod:`gtrig.io` reads and writes files; :mod:`gtrig.cli` and the ``plots`` modules sit on top.
"""

__version__ = "0.1.0"

from gtrig.errors import GtrigError

__all__ = ["GtrigError", "__version__"]
