"""The application: the only code that knows all four parts (graph launcher, demo, evaluation, qtree CLI)."""
