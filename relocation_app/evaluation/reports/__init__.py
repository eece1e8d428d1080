"""The evaluation's tables, figures and the comparison with the paper's numbers."""
