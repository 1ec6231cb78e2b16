"""prepare stage of gnssacc."""
