"""gainlink.hil: hardware-in-the-loop bridge between a plant (FMU or built-in model) and the firmware.

Sub-packages, by part:

- :mod:`.plants`: the plant base class and registry, built-in models, FMUs through fmpy, the
  project's FMUs built from source, linearisation of an FMU to a spec;
- :mod:`.links`: the transport base class and registry, CAN (python-can, DBC layout, firmware CAN
  node), MAVLink (pymavlink), reference controller nodes, a Linux VM with a real SocketCAN vcan0;
- :mod:`.run`: scenario, faults, scheduling, the controller peer process, the bridge loop, metrics,
  report and the anti-windup study.

Entry points: ``gainlink hil run|dbc|fmu|study``, ``gainlink linearize``, ``gainlink firmware run --can``.
The vehicle-side MAVLink parameter upload is :mod:`gainlink.mavlink`.
"""
