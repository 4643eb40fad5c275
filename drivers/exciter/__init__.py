"""Plate exciter drivers: one interface, Modbus and CAN back ends."""
