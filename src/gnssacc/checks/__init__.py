"""checks stage of gnssacc."""
