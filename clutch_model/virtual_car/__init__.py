"""The virtual test car: seeded synthetic campaigns, bench tables and the sample bags."""
