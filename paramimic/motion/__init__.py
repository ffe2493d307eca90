"""Reference motions: procedural keyframes, clip files, displacement ⊕ and time warp ([L21]
§3), and the fitness of an episode against its reference ([L21] Eq. 10)."""
