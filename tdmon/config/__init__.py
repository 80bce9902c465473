"""Pydantic models of the TOML files and adapters to model arguments."""
