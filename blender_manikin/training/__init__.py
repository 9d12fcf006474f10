"""Training pipeline for the MANIKIN network (torch; never shipped with the add-on).

``dataset``         BVH folder/archive -> cached clips with ground truth -> window batches
``torch_geometry``  differentiable rotations, swivel solver (eq. 7) and FK in torch
``model``           the Transformer backbone with a global and a local head
``losses``          MANIKIN (eq. 15) and network-only ("fk") losses and metrics
``train``           ``python -m blender_manikin.training.train --bvh SRC --out DIR``
``export``          ``python -m blender_manikin.training.export --checkpoint DIR/checkpoint.pt --out X.onnx``

``build_addon.py`` excludes this package from the shipped add-on; torch is
imported only here.
"""
