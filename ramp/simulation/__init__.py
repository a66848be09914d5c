"""`ramp sim …`: the simulation entry points that wire `firmware_like/` emulators, the backend
and the autonomy together on one clock. Like `ramp.sim` (the `ramp run --sim` backplane), this
package may import `firmware_like/`; nothing else in `ramp/` does.
"""
