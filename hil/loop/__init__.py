"""One HIL run and what surrounds it: the scenario file (:mod:`.scenario`), injected faults
(:mod:`.faults`), pacing, CPU placement and real-time settings (:mod:`.scheduler`), the controller
peer process (:mod:`.controller`), the loop itself (:mod:`.bridge`), what a run feeds and records
(:mod:`.plan`, shared with the in-process SIL loop :mod:`.sil`), metrics (:mod:`.metrics`), the report
folder (:mod:`.report`) and the anti-windup study (:mod:`.study`)."""
