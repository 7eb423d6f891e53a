"""ROS 2 without a ROS install (thesis §4.4.1, issue L): message types and CDR through ``rosbags``,
rosbag2 recordings in MCAP and sqlite3, and the rmw_zenoh naming and wire conventions.

Modules: :mod:`.types` (type store, CDR codec, RIHS01 hashes), :mod:`.convert` (CKM payloads ⇄ ROS
messages), :mod:`.compat` (CKM MessageTypes against ROS types, for ``verify``), :mod:`.bag`
(record and replay rosbag2 bags), :mod:`.wire` (ROS-typed topics as CDR on the transports),
:mod:`.rmw_zenoh` (key expressions, liveliness tokens, QoS strings, attachments), :mod:`.bridge`
(CKM topics to and from rmw_zenoh nodes). Nothing here imports plugins or the editor.
"""
