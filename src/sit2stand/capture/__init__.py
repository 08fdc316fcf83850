"""Live capture: motion-capture systems' real-time protocols in, sit2stand's marker and plate streams out.

Plain Python, no rclpy (the ``mocap_bridge`` node is a thin shell over it):

* :mod:`.qtm_protocol`: the Qualisys Track Manager real-time protocol, version 1.x, as its vendor documents it
  (packets, commands, XML parameters, the 3D and force data components): an encoder for our server, a decoder
  for tests (the bridge decodes with the vendor's own client, ``qtm-rt``).
* :mod:`.natnet_protocol`: OptiTrack's NatNet 3.0-4.1 (server info, model definitions, frames of data), written as
  the inverse of what the ``natnet`` client package reads.
* :mod:`.recording`: what a capture system streams (labelled markers [mm], plates [N, N m, mm] in its own axes),
  built from a C3D file.
* :mod:`.server`: ``sit2stand serve-c3d``: a capture-system stand-in serving a recording at the file's rate over
  the QTM protocol (TCP, or UDP streaming) or NatNet (UDP unicast, markers only).
* :mod:`.convert`: a streamed frame to the lab frame and SI units (the same arithmetic as ``import-c3d``), the
  capture clock mapped once to the ROS clock, dropped-frame counting, the reconnect policy.
* :mod:`.clients`: the QTM (``qtm-rt``) and NatNet (``natnet``) client loops that feed :mod:`.convert`.
"""
