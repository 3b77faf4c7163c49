"""Sect. VI as code: object splits, figures, the evaluation protocol and its report.

- ``splits``    random known/novel object splits with whole-trial hold-out
- ``metrics``   accuracy, novelty detection, AUROC, harmonic mean, confusion and Jaccard matrices
- ``protocol``  fit every method on every split and measure every figure
- ``report``    report.md beside the paper's Tables II-IX, and Figs. 7-8 as PNGs
- ``summary``   the plain-text tables ``evaluate`` prints, each figure once
- ``raw_report`` report.md and PNGs of the raw-trial protocol (``raw``)
- ``plots``     the generic figures (matplotlib), importing no protocol and no report
- ``cells``     the cells of the reports' markdown tables
"""

from app.evaluation.splits import SplitError, ZslSplit, make_zsl_splits

__all__ = ["SplitError", "ZslSplit", "make_zsl_splits"]
