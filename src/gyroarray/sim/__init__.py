"""MuJoCo rate table and noise injector (issue 3)."""
