"""gainlink.hil: hardware-in-the-loop bridge between a plant (FMU or built-in model) and the firmware."""
