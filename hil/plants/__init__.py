"""Plants the bridge simulates: the base class and registry (:mod:`.base`), built-in models
(:mod:`.models`), FMUs through fmpy (:mod:`.fmu`), the project's own FMUs built from source
(:mod:`.build`) and FMU linearisation to a spec (:mod:`.linearize`)."""
