"""clutch_sim: the `clutch-sim` command line over clutch_model (and clutch_sim_ros for live use)."""
