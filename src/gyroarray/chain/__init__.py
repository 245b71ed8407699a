"""The chain: a scenario run through the simulator and the estimators; a record compared with a model (diagnose, fit, ladder), FDI scores."""
