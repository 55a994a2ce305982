"""Developer tools run as ``python -m daq.tools.<name>``: not part of the acquisition path."""
