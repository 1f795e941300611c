"""planhrc: human-robot cooperative manipulation of articulated objects."""
__version__ = "0.1.0"
