"""Discrepancy diagnosis: show what the baseline gets wrong, name the cause among the
mechanism catalog (or say `none` / `unexplained`), extend the model and measure the gain."""
