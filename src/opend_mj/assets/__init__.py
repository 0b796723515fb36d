"""Asset stage: cabinet sources (procedural or PartNet-Mobility) compiled into an MJCF dataset.

``procedural`` writes sources, ``sources`` reads them, ``meshes`` turns meshes into convex hulls,
``compiler`` writes one cabinet's MJCF, ``dataset`` builds, filters and splits many, ``checks`` tests a
compiled cabinet's physics. ``layout`` is the compiled dataset's file contract, the one module the
runtime (``sim``, ``evaluation``) reads, so that loading a cabinet never imports the compiler.
"""
