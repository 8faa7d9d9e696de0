"""Geometry below every other layer (imports numpy, scipy, Pinocchio's SE3, coal and CasADi only):
rotation and pose conventions (:mod:`.spatial`), exact and smooth distances between primitives
(:mod:`.distance`), splines and time laws (:mod:`.splines`)."""
