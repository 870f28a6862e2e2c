"""Close the loop (issue 6): residual analysis, attribution of the residual to a missing effect, and the
augmentation loop that adds it and re-fits (``vehid diagnose``)."""

from .loop import Diagnosis, diagnose

__all__ = ["Diagnosis", "diagnose"]
