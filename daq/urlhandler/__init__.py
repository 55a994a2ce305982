"""pyserial URL handlers of this project (``rig://``); see daq.transport.register_url_handler."""
