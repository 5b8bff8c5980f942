"""Stands in for D4RL (its import registers the datasets; gym.py serves ours)."""
