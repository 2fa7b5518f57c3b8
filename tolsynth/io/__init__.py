"""Results out of the process: tables (CSV, JSON, Parquet) and design reports."""
