"""outputs stage of gnssacc."""
