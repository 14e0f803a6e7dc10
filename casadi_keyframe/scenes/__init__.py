"""Scene builders: what problem files, studies and benchmarks set up, kept in the package so
they work from an installed copy.

* :mod:`.flocks`: a flock control problem in a few lines (start blobs, stored wander);
* :mod:`.cloths`: a cloth control problem and target shapes of a sheet;
* :mod:`.capes`: a cape sewn to an animated character and its passive source clips (fig. 6).

Import from the modules; this face imports nothing, so loading one scene loads no other.
"""
