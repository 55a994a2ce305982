"""One processing stage for live acquisition and replay: the 50 Hz filter, the regime monitor, rolling SINDy."""
