"""Links between the bridge and the controller: the transport base class and registry (:mod:`.base`),
CAN through python-can (:mod:`.can`, layout and DBC in :mod:`.can_layout`, the firmware's CAN node
launcher in :mod:`.can_firmware`, a Python reference node in :mod:`.can_node`), MAVLink through
pymavlink (:mod:`.mavlink`, reference node :mod:`.mavlink_node`) and a small Linux VM with a real
SocketCAN ``vcan0`` (:mod:`.vcan_vm`)."""
