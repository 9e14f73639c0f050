"""Replay, compare, diff and inspect recorded corraoi runs. Reads logs; never simulates."""
