# SPDX-License-Identifier: MIT
"""Python client of the vafmd daemon (protocol/wire.md), on Debian's python3-zmq and numpy (h5py for
the HDF5 loader).

    from vafm_client import Client, Stream, load_h5
    c = Client("tcp://127.0.0.1:5555")
    c.set(k_N_per_m=0.2)
    with Stream("tcp://127.0.0.1:5556") as s:       # subscribe before starting: no block is missed
        run_id = c.curve(index=0)["run_id"]
        run = s.run(run_id)                          # a Run: channels as numpy arrays, events, run.end
        print(run.end["result"]["pulloff_spring_N"], run["force_N"].min())
    f = load_h5("curves.h5")                         # HDF5 files of protocol/hdf5.md (any program's)

The 72-byte data header is decoded here with struct, per wire.md §4 (no C code is imported).
`Daemon` (vafm_client.spawn) starts a private vafmd on ipc:// endpoints, for tests and examples;
`vafm_client.pytest_plugin` gives each pytest test a vafmd (fixture `vafmd`; docs/daemon.md, "Testing your
acquisition code").
"""
from .client import (CHANNELS, DEFAULT_PUB, DEFAULT_REP, HEADER, MAGIC, Client, DaemonError, GapError,
                     Header, Run, Stream, TransportError, TruncatedError, decode_header)
from .h5 import Curve, H5File, load_h5
from .spawn import Daemon

__all__ = ["CHANNELS", "DEFAULT_PUB", "DEFAULT_REP", "HEADER", "MAGIC", "Client", "Curve", "Daemon",
           "DaemonError", "GapError", "H5File", "Header", "Run", "Stream", "TransportError", "TruncatedError",
           "decode_header",
           "load_h5"]
__version__ = "0.8.0"
