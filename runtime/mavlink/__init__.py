"""gainlink.mavlink: the vehicle side of MAVLink — gains as parameters (:mod:`.params`), the pymavlink
connection (:mod:`.link`), the parameter protocol client (:mod:`.session`), the verified upload with
rollback (:mod:`.upload`), and a lossy UDP relay used to prove it under loss (:mod:`.relay`)."""
