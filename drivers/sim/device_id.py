"""Modbus Read Device Identification (function 43, MEI type 14) for the simulated drives.

pymodbus answers function 43/14 from one process-wide identity (its ModbusControlBlock), and
the station runs several simulated rigs, with different profiles, in one process (the tests).
So each server gets its own request class, answering per unit id from its own table: objects
0 VendorName, 1 ProductCode, 2 MajorMinorRevision (the basic objects). A drive whose profile
says it does not answer 43/14 (`[protocol] device_identification = false`) gets exception 01
(illegal function), as a real drive without the function would answer.
"""

from __future__ import annotations

from typing import Mapping

from pymodbus.constants import DeviceInformation, ExcCodes
from pymodbus.exceptions import NoSuchIdException
from pymodbus.pdu import ExceptionResponse
from pymodbus.pdu.mei_message import ReadDeviceInformationRequest, ReadDeviceInformationResponse

BASIC_OBJECTS = {0x00: "vendor", 0x01: "product", 0x02: "firmware"}
"""Object id -> the profile's [identity] key that fills it."""


def device_objects(identity: Mapping[str, str]) -> dict[int, bytes]:
    """The basic objects (0..2) of a drive from its profile's [identity]."""
    return {oid: str(identity.get(key, "")).encode("ascii", "replace") for oid, key in BASIC_OBJECTS.items()}


def install(server, objects_by_unit: Mapping[int, Mapping[int, bytes] | None]) -> None:
    """Make `server` (a pymodbus server) answer function 43/14 from `objects_by_unit`: unit id ->
    its objects, or None for a drive that does not implement the function (exception 01). A unit
    id not in the table is not answered (no drive there)."""

    class _Request(ReadDeviceInformationRequest):
        async def datastore_update(self, context, device_id: int):  # noqa: ARG002 (pymodbus' signature)
            if device_id not in objects_by_unit:
                raise NoSuchIdException(f"no drive at unit id {device_id}")
            objects = objects_by_unit[device_id]
            if objects is None:
                return ExceptionResponse(self.function_code, ExcCodes.ILLEGAL_FUNCTION)
            if self.read_code == DeviceInformation.SPECIFIC:
                if self.object_id not in objects:
                    return ExceptionResponse(self.function_code, ExcCodes.ILLEGAL_ADDRESS)
                info = {self.object_id: objects[self.object_id]}
            else:  # basic, regular, extended: this drive has only the basic objects
                info = {oid: value for oid, value in objects.items() if oid >= self.object_id} or dict(objects)
            return ReadDeviceInformationResponse(read_code=self.read_code, information=info, dev_id=device_id,
                                                 transaction_id=self.transaction_id)

    decoder = server.decoder
    table = {code: dict(subs) for code, subs in decoder.pdu_sub_table.items()}  # this server's own copy
    table.setdefault(_Request.function_code, {})[_Request.sub_function_code] = (_Request, ReadDeviceInformationResponse)
    decoder.pdu_sub_table = table
