"""sweeplog."""
