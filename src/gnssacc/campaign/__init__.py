"""campaign stage of gnssacc."""
