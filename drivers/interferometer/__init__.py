"""Serial laser interferometer: line protocol (protocol.py) and client (client.py).

The protocol is documented in docs/interferometer-protocol.md.
"""

from drivers.interferometer.client import SerialInterferometer
from drivers.interferometer.protocol import InstrumentError, ProtocolError

__all__ = ["SerialInterferometer", "InstrumentError", "ProtocolError"]
