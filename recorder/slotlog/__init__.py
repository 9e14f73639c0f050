"""slotlog."""
