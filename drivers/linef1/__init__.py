"""The µLine-F1 / HPI-3D laser interferometer (Lasertex; Status Pro): its streaming serial protocol
(protocol.py) and the station's client for it (client.py). docs/interferometer-protocol.md."""

from drivers.linef1.client import LineF1Interferometer, StreamReading

__all__ = ["LineF1Interferometer", "StreamReading"]
