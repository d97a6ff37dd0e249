"""Learned exploration policies for the harness (``naruto-benchmark``)."""
