"""Replay engines that run the compiled firmware instead of the Python models.

- ``native``: the host build of the C library through ctypes, one call per block of samples (:mod:`.native`, the
  float32 law's);
- ``qemu``: a Cortex-M image under ``qemu-system-arm``, samples through semihosting file I/O (:mod:`.qemu`).

Each other law's engines are in its own package (``gainlink.laws.fixed.engines``, ``gainlink.laws.scheduled.native``
and ``.qemu``).

Which engine runs an artifact is its law's choice (:meth:`gainlink.laws.Law.replay`, ``--engine native|qemu``);
each module is imported on first use, so a replay never imports a toolchain it does not need.
"""
