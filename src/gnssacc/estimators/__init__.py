"""estimators stage of gnssacc."""
