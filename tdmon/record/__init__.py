"""The flight recorder (MCAP), Rerun views and the post-well report."""
