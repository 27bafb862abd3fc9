"""Plants the bridge simulates: the base class and registry (:mod:`.base`), building one from a scenario's
``[plant]`` table (:mod:`.config`), built-in models (:mod:`.models`), FMUs through fmpy — the ``fmu`` kind and
its choice of interface (:mod:`.fmu_interface`), Co-Simulation (:mod:`.fmu`), Model Exchange on fmpy's CVode
(:mod:`.fmu_me`, FMI 2.0 and 3.0 through :mod:`.fmi_me`), what they share (:mod:`.fmi`) — the project's own FMUs
built from source (:mod:`.build`), linear plants from any spec or artifact with perturbation (:mod:`.linear`),
user plants in Python (:mod:`.python`), and FMU linearisation to a spec (:mod:`.linearize`, Jacobians by
:mod:`.jacobian`; Co-Simulation-only FMUs identified from doStep responses, :mod:`.identify`)."""
