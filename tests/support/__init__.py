"""Helpers shared by the test modules (no tests here; the shared fixtures are in ``tests/conftest.py``).

``paths`` (the checkout's folders), ``cli`` (gainlink in-process), ``net`` (ports and multicast groups private to a
test), ``hil`` (scenarios and CAN transports), ``mavlink`` (the MAVLink firmware app and a closed loop over it),
``oracles`` (independent checks of the law), ``thirdparty`` (FMUs from PyPI), ``hostile_traffic`` (a flood
generator, also run as a script), ``campaign_plants`` (a plant Dask workers import by name).
"""
