"""The same controller against the simulator or a real Panda, over LCM (issue 34).

Drake's hardware_sim pattern: a *station* (:mod:`.station`) simulates the Panda, its
camera and the target and speaks drake-franka-driver's channels (PANDA_STATUS at 1 kHz,
PANDA_COMMAND) and the camera's; a *controller* (:mod:`.controller`) holds only what a
real robot gives (joint state, frames) and runs the NF law. :mod:`.config` holds the
bus, the channels, the mode and the timeouts. ``geovs-drake station`` and
``geovs-drake controller`` run them as two processes; docs/hardware.md says how.
"""
