"""Results to look at: the design for ParaView (VTU), its outline for CAD (SVG, DXF), an animation of the
mechanism in motion, and the `ffr-jax animate` / `ffr-jax export` commands. File output only; nothing
here runs inside jit-traced code."""
