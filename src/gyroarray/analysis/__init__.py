"""Statistics shared by simulation fitting, estimators and reports.

Lives in its own folder (``analysis/``) because the simulator (fitting
effects back), the estimators (scoring fused output) and the reports all
need the same Allan/Hadamard deviation, confidence intervals and noise fits.
"""
