"""gainlink: state-space controller design to a verified, running firmware loop.

The design side lives here (``import gainlink``): plant specs, analysis, discrete design,
the versioned gain artifact, C code generation, the float64 reference of the control law,
and the ``gainlink`` command line. The bridge side is :mod:`gainlink.hil`.
"""

__version__ = "0.1.0"
