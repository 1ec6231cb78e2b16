"""analysis stage of gnssacc."""
