"""The modelling features a scene needs and an engine declares: one vocabulary.

A scene names what it needs (:meth:`truestep.reference_impl.model.ParticleModel.features`,
:meth:`truestep.cases.case.OdeSpec.features`); an adapter declares what it models in its
``capabilities``; a case runs on an engine when the first is a subset of the second. Both
sides use :class:`Feature`, a string enumeration, so a feature is spelled once and a
misspelt one cannot match by accident; a plugin's adapter may still declare plain strings
(they compare equal to the members).
"""

from __future__ import annotations

from enum import StrEnum


class Feature(StrEnum):
    """A modelling feature, by the name cases, adapters and ``truestep list`` show."""

    ODE = "ode"
    """A first-order ODE system ``y' = f(t, y)``."""
    SECOND_ORDER = "second-order"
    """An ODE whose state splits into positions and velocities."""
    POINT_MASSES = "point-masses"
    """Particles: masses at points, no rotation."""
    PLANAR = "2d"
    """Motion in a plane."""
    SPATIAL = "3d"
    """Motion in space."""
    UNIFORM_GRAVITY = "uniform-gravity"
    """One acceleration for every particle, m/s²."""
    DRAG = "drag"
    """Linear drag against the velocity."""
    SPRINGS = "springs"
    """Springs between particles."""
    SPRING_DAMPING = "spring-damping"
    """Dampers along springs or anchors."""
    ANCHORED_SPRINGS = "anchored-springs"
    """Springs from particles to fixed points."""
    UNIVERSAL_GRAVITATION = "universal-gravitation"
    """Newton's gravitation between particles or toward fixed masses."""
    FORCE_FIELDS = "force-fields"
    """Forces that depend on position (the lecture's force fields)."""
    PLANES = "planes"
    """Collision planes with restitution."""
    FRICTION = "friction"
    """Coulomb friction on a plane."""
    THIN_WALLS = "thin-walls"
    """Planes of finite thickness, which a fast particle may pass."""
    EMITTERS = "emitters"
    """Particles born during the run, with lifetimes."""
    PINNED_PARTICLES = "pinned-particles"
    """Static particles that do not move (strands, hung cloth)."""
    IMPULSES = "impulses"
    """Impulses applied at given times."""
