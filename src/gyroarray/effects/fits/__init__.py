"""The fit side of the effects: what a record says about each effect's parameters."""
