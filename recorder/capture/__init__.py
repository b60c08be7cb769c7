"""Real-time capture: the recorder (capture thread, bounded queue, writer), its counters, and the frame sources."""
