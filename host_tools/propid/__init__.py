"""propid host tools: MAVLink telemetry, flight logs, replay and analyses."""

__version__ = "0.1.0"
