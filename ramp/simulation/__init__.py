"""`ramp sim …`: the simulation entry points that wire `firmware_like/` emulators, the backend
and the autonomy together on one clock, and `backplane` (the `ramp run --sim` backplane). This
package may import `firmware_like/`; nothing else in `ramp/` does.
"""
