"""Reading sessions for the API: frames from verified copies (frames), and time/topic slices as MCAP (mcap_slice)."""
