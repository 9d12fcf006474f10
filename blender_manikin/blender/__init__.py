"""Blender-side writers and readers of blender_manikin (imports bpy).

* :mod:`.armature` -- the body armature (bone layout, rolls) and the mapping
  from body-model local rotations to pose-bone quaternions.
* :mod:`.keying` -- bulk F-curve writing on both action APIs (4.2-4.3
  ``action.fcurves``; 4.4+/5.x slotted actions and channelbags).
* :mod:`.writer` -- puts a solved :class:`~blender_manikin.core.pose_result.PoseResult`
  into the scene (armature, action, swivel properties, tracker empties),
  all-or-nothing.
* :mod:`.scene_trackers` -- samples animated scene objects / bones as trackers.
* :mod:`.solve_job` -- the solve as a cancellable job shared by the operator
  and the command line.

Nothing in :mod:`blender_manikin.core` imports from here.
"""
