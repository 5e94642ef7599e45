"""Adapters for real public datasets (readers, converters, downloaders)."""
