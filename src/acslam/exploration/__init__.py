"""Exploration (thesis §4.5-4.6): frontier detection, frontier clustering, allocation."""
