"""Real-hardware side of relaxgrip: the MCU protocol, transports and (later) cameras.

Nothing here needs pyserial to import; the serial transport asks for it when
it is built (``pip install 'relaxgrip[hardware]'``).
"""
