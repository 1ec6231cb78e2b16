"""core stage of gnssacc."""
