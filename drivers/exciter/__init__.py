"""Plate exciter drivers: one interface; Modbus, CAN (own frame set) and CiA 402 (CANopen) back ends."""
