"""Live viewers: a Rerun viewer probed, spawned or served on the web, and a Foxglove WebSocket
server."""
