"""Independent checks of the one model: a second derivation and a multibody engine."""
