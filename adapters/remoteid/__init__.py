"""Remote ID (ASTM F3411 / ASD-STAN prEN 4709-002, OpenDroneID): the broadcast message
decoder (:mod:`adapters.remoteid.f3411`, pure), the operator's side sent to vehicles and the
OPEN_DRONE_ID_* MAVLink messages read from them. docs/remote-id.md."""
