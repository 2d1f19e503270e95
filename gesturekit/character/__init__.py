"""The character: one skinned body that every view of a motion shows.

A motion is joint positions; a character needs joint rotations. :mod:`.rig`
turns positions into rotations by one solve (:func:`~gesturekit.character.rig.solve_pose`),
the same one the BVH and glTF exports write, so the page, the MP4, the BVH and
the glTF file show one pose. :mod:`.mesh` makes the body, bound to the rig's
rest pose; :mod:`.skin` places its vertices for a pose (linear blend skinning,
as a GPU does); :mod:`.look` holds the colours, light and camera the page and
the MP4 share.
"""
