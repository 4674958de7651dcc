"""Agents that steer the flat body onto stationary ellipses (Stable-Baselines3)."""
