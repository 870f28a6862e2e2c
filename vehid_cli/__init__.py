"""vehid: vehicle and suspension parameter identification."""

__version__ = "0.1.0"
