"""The Zenoh session a process opens: the transport (one session, typed publishers, latest-wins subscribers), the
installation's credentials and access control, TLS and the master lock, liveliness, refused links and the probe that
tells a connecting side why it found no peer.

It imports :mod:`teleop.config`, :mod:`teleop.wire`, :mod:`teleop.recording` (the journal) and :mod:`teleop.timing`.
"""
