"""Simulated devices speaking their real protocols on real transports (ptys, TCP sockets)."""
