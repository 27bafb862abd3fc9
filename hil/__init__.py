"""gainlink.hil: hardware-in-the-loop bridge between a plant (FMU or built-in model) and the firmware.

Modules, by what they hold:

- plants: :mod:`.plant` (ABC + registry), :mod:`.models` (cart pendulum, quadrotor lateral,
  Wood-Berry, linear), :mod:`.fmu_plant` (FMI 2.0/3.0 Co-Simulation via fmpy), :mod:`.fmu_build`
  (the project's plant FMUs from ``fmus/``), :mod:`.linearize` (FMU -> spec TOML);
- link: :mod:`.transport` (ABC + registry), :mod:`.can_layout` (DBC), :mod:`.can_transport`
  (python-can), :mod:`.can_node` (Python reference controller node), :mod:`.controller` (peer process);
- run: :mod:`.scenario`, :mod:`.faults`, :mod:`.scheduler`, :mod:`.bridge`, :mod:`.metrics`,
  :mod:`.report`, :mod:`.study` (saturation study);
- real SocketCAN: :mod:`.vcan_vm` (a small Linux VM with vcan0).

Entry points: ``gainlink hil run|dbc|fmu|study``, ``gainlink linearize``, ``gainlink firmware run --can``.
"""
