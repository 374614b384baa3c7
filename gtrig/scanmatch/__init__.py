"""Onboard scan matching: relative-pose ground truth and validation poses from the robot's own scans.

Steps, one module each: :mod:`~gtrig.scanmatch.scan` (ranges to matchable points, stops, merging),
:mod:`~gtrig.scanmatch.icp` (point-to-line ICP, Censi 2008, with its covariance),
:mod:`~gtrig.scanmatch.genetic` (the seeds' real-coded genetic matcher),
:mod:`~gtrig.scanmatch.covariance` (errors shared by many points),
:mod:`~gtrig.scanmatch.accept` (the acceptance test), :mod:`~gtrig.scanmatch.pairs` (candidate pairs
over a guessed trajectory), :mod:`~gtrig.scanmatch.validate` (validation stops),
:mod:`~gtrig.scanmatch.mapmatch` (alignment to a building map) and :mod:`~gtrig.scanmatch.mounting`
(planar hand-eye calibration of the scanners' mountings). Methods and figures: docs/scanmatch.md.
"""
