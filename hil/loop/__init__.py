"""The closed loop, written once for every law and every endpoint: the scenario file (:mod:`.scenario`), what a run
feeds and records (:mod:`.plan`), injected faults (:mod:`.faults`), pacing, CPU placement and real-time settings
(:mod:`.scheduler`), the controller peer process (:mod:`.controller`), the loop body (:mod:`.closed_loop`) and its
endpoints (:mod:`.endpoints`: in process, over a link, the image over its FIFOs), the one dispatcher
(:mod:`.bridge`), PIL (:mod:`.pil`), the twins computed after the run (:mod:`.twins`, :mod:`.model_twin`), metrics
(:mod:`.metrics`), the report folder (:mod:`.report`), the anti-windup study (:mod:`.study`) and the scheduled
showcase (:mod:`.showcase`)."""
