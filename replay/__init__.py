"""replay: reading recordings, recovering broken ones, and (with its issue) playback.

May import ident and daq.
"""
