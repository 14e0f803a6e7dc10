"""Scene builders: what problem files, studies and benchmarks set up, kept in the package so
they work from an installed copy.

* :mod:`.flocks`: a flock control problem in a few lines (start blobs, stored wander);
* :mod:`.flock_path`: fig. 3's flock, which follows a path (also the studies' control case);
* :mod:`.cloths`: a cloth control problem and target shapes of a sheet;
* :mod:`.sheets`: the hanging test sheet swung forward (studies, tests, benchmarks);
* :mod:`.skeleton`: a character of capsules, its poses and their geometry;
* :mod:`.animations`: the character's walk, fall and transitions, a pose at any time;
* :mod:`.capes`: a cape sewn to an animated character and its passive source clips (fig. 6);
* :mod:`.cape_tracking`: the cape blend's warm start, a PD tracking controller that lands;
* :mod:`.maths`: rotations and smooth ramps the scenes share.

Import from the modules; this face imports nothing, so loading one scene loads no other.
"""
