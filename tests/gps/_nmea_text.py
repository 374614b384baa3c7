"""Hand-made NMEA sentences for the tests."""

from __future__ import annotations


def cs(body: str) -> str:
    """``$body*HH`` with its checksum."""
    x = 0
    for ch in body.encode():
        x ^= ch
    return f"${body}*{x:02X}"


GGA = "GPGGA,{t},4530.36844637,N,00909.97033083,E,{q},8,0.9,129.085,M,48.022,M,1.0,0000"
GST = "GPGST,{t},0.02,0.020,0.010,30.0,0.018,0.013,0.030"
