"""PioneeR: social navigation from positive and negative demonstrations and rules."""

__version__ = "0.1.0"
