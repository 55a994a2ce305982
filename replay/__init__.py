"""replay: recordings after the fact: formats (one module per format, one suffix table), paced playback
through the live pipeline, recovery of damaged files, and the ``replay`` command.

May import ident and daq.
"""
