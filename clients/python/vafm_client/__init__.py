# SPDX-License-Identifier: MIT
"""Python client of the vafmd daemon (protocol/wire.md), on Debian's python3-zmq and numpy.

    from vafm_client import Client, Stream
    c = Client("tcp://127.0.0.1:5555")
    c.set(k_N_per_m=0.2)
    with Stream("tcp://127.0.0.1:5556") as s:       # subscribe before starting: no block is missed
        run_id = c.curve(index=0)["run_id"]
        run = s.run(run_id)                          # a Run: channels as numpy arrays, events, run.end
        print(run.end["result"]["pulloff_spring_N"], run["force_N"].min())

The 72-byte data header is decoded here with struct, per wire.md §4 (no C code is imported).
"""
from .client import (CHANNELS, DEFAULT_PUB, DEFAULT_REP, HEADER, MAGIC, Client, DaemonError, GapError,
                     Header, Run, Stream, TransportError, decode_header)

__all__ = ["CHANNELS", "DEFAULT_PUB", "DEFAULT_REP", "HEADER", "MAGIC", "Client", "DaemonError", "GapError",
           "Header", "Run", "Stream", "TransportError", "decode_header"]
__version__ = "0.1.0"
