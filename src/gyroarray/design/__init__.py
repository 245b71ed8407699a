"""Array design: the analytic predictor and the recommendation."""
