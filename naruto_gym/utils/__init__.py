"""Utilities shared by the package's layers."""
