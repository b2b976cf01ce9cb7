"""Baselines the study compares C against (the simple ones live in terrapref.planner.policy)."""
