"""Simulated devices speaking their real protocols on real transports (ptys, TCP sockets, virtual CAN): the
ZX-L laser amplifiers and the Modbus, CAN and CiA 402 plate drives.

Must not import daq or service, and of drivers only the codecs and address maps
(tests/test_dependency_rules.py)."""
