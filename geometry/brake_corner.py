"""Passenger-car front brake corner: ventless disc with hat, two pads, piston and floating caliper.

SI units (metres), axis z, disc mid-plane z = 0; the pads are centred on the +x axis (θ = 0), the
inboard side (piston, caliper housing) is z < 0 and the hat rises towards z > 0 (outboard).

Parts (cell tags of :data:`geometry.tags.BRAKE_CORNER_VOLUMES`); a part may hold several OCC
volumes, all in its physical group:

* ``disc``: friction ring ``r_i <= r <= r_o``, ``|z| <= h/2``; hat wall ``r_i - t_w <= r <= r_i`` from
  ``z = -h/2`` up to the flange; flange ``r_f <= r <= r_i``, ``z_top - t_f <= z <= z_top`` with
  ``z_top = h/2 + hat_depth``.  The flange is built as two annuli split at ``bolt_face_outer_radius``;
  all disc volumes are fragmented together (conforming, connected).
* ``lining_inner``/``lining_outer`` and ``backplate_inner``/``backplate_outer``: annular sectors; each
  lining is fragmented with its backplate (bonded), never with the disc.
* ``piston``: solid cylinder in the caliper bore, front face on the inner backplate.
* ``caliper``: housing (with the piston bore), bridge over the disc rim, two fingers on the outer
  backplate and two guide-pin ears with holes, fused into one volume.

Touching parts of different groups (disc/lining, piston/backplate, piston/bore, finger/backplate)
are separate coincident surfaces meshed independently, so their nodes are distinct.  With
``matching=True`` the lining footprint is imprinted on the disc friction faces and each lining
contact face receives a copy of the disc patch mesh (``setPeriodic``, identity): coincident nodes.

Face tags (:data:`geometry.tags.BRAKE_CORNER_FACES`): ``disc_bolt_face`` is the *outboard* face
``z = z_top`` of the inner flange annulus ``r_f <= r <= bolt_face_outer_radius`` (the hub/wheel
clamps the flange there); ``disc_friction_inner``/``outer`` are the whole ring faces ``z = -/+ h/2``.

Meshing: constant size per part (``disc``/``pad``/``caliper``, prescribed on the points of each part),
refined round the guide holes and the hat's centre bore.  :func:`brake_corner_mesh` tries gmsh's
Delaunay (reproducible) with up to three seeds, then HXT (not reproducible run to run), and keeps the
first mesh whose curved second-order tetrahedra all have SICN >= 0.1 (gmsh 4.8 here has no working
high-order optimiser, so an inverted curved element can only be avoided by re-meshing).
"""
from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass

from mpi4py import MPI

from geometry.gmsh_io import MIN_SICN as _MIN_SICN
from geometry.gmsh_io import GmshModel, MeshData, search_meshes, to_dolfinx
from geometry.tags import BRAKE_CORNER_FACES, BRAKE_CORNER_VOLUMES

_IDENTITY = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]
_CIRCLE_SEGMENTS = 12      # guide holes: at least this many elements round the circumference
_BORE_SIZE = 0.5           # size at the hat's centre bore, x flange_thickness (graded out over 2 x)
# meshing attempts (Mesh.Algorithm3D, Mesh.RandomSeed): Delaunay is reproducible, HXT (10) is not
_ATTEMPTS = ((1, 1), (1, 2), (1, 3), (10, 1))
_MESH_SIZES = ("disc_mesh_size", "pad_mesh_size", "caliper_mesh_size")


def _f(default, doc: str):
    """Dataclass field with a ``doc`` (read by the scene schema)."""
    return dataclasses.field(default=default, metadata={"doc": doc})


@dataclass(frozen=True)
class BrakeCornerParams:
    """Dimensions [m, degrees] and mesh sizes [m] of the brake corner; validated on creation."""

    # disc
    disc_outer_radius: float = _f(0.144, "friction-ring outer radius [m]")
    disc_inner_radius: float = _f(0.085, "friction-ring inner radius = hat outer radius [m]")
    disc_thickness: float = _f(0.022, "friction-ring thickness [m]")
    hat_depth: float = _f(0.034, "outboard friction face -> outer (bolt) face of the flange [m]")
    hat_wall_thickness: float = _f(0.007, "radial thickness of the hat wall [m]")
    flange_thickness: float = _f(0.008, "thickness of the hat flange [m]")
    flange_inner_radius: float = _f(0.030, "radius of the hat's centre bore [m]")
    bolt_face_outer_radius: float = _f(0.060, "outer radius of the bolt face annulus [m]")
    # pads
    lining_inner_radius: float = _f(0.098, "lining inner radius [m]")
    lining_outer_radius: float = _f(0.142, "lining outer radius [m]")
    lining_angle_deg: float = _f(60.0, "lining sector angle, centred on +x [deg]")
    lining_thickness: float = _f(0.011, "lining thickness [m]")
    backplate_margin: float = _f(0.004, "radial overhang of the backplate beyond the lining [m]")
    backplate_angle_deg: float = _f(70.0, "backplate sector angle [deg]")
    backplate_thickness: float = _f(0.0055, "backplate thickness [m]")
    # piston
    piston_radius: float = _f(0.027, "piston (and bore) radius [m]")
    piston_length: float = _f(0.025, "piston length; its front face is on the inner backplate [m]")
    piston_radial_position: float = _f(0.120, "x of the piston axis (y = 0) [m]")
    # caliper
    caliper_gap: float = _f(0.001, "housing front face -> inner backplate back face [m]")
    housing_inner_x: float = _f(0.085, "x of the housing's inner end [m]")
    caliper_outer_x: float = _f(0.172, "x of the caliper's outer end (housing, bridge, fingers) [m]")
    caliper_half_width: float = _f(0.045, "|y| extent of housing and bridge [m]")
    housing_thickness: float = _f(0.036, "z extent of housing and ears [m]")
    bridge_thickness: float = _f(0.022, "x extent of the bridge (inner face at caliper_outer_x - this) [m]")
    finger_thickness: float = _f(0.015, "z extent of the fingers [m]")
    finger_inner_x: float = _f(0.095, "x of the fingers' inner ends [m]")
    finger_y_inner: float = _f(0.010, "fingers span finger_y_inner <= |y| <= finger_y_outer [m]")
    finger_y_outer: float = _f(0.040, "see finger_y_inner [m]")
    ear_x: float = _f(0.120, "x of the guide-pin axes (ear centres) [m]")
    ear_width: float = _f(0.030, "x extent of a guide-pin ear [m]")
    ear_length: float = _f(0.020, "y extent of an ear beyond the housing [m]")
    guide_hole_radius: float = _f(0.006, "guide-pin hole radius [m]")
    # mesh
    mesh_size: float = _f(0.008, "target element size [m] (default: about 160k P2 displacement DOFs)")
    disc_mesh_size: float | None = _f(None, "disc element size [m]; None -> mesh_size")
    pad_mesh_size: float | None = _f(None, "lining + backplate element size [m]; None -> min(mesh_size, disc)")
    caliper_mesh_size: float | None = _f(None, "caliper + piston element size [m]; None -> mesh_size")
    matching: bool = _f(False, "imprint the lining footprints on the disc and copy their mesh (coincident nodes)")

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.name == "matching":
                if not isinstance(v, bool):
                    _bad(f.name, f"must be a boolean (got {v!r})")
            elif v is None and f.name in _MESH_SIZES:
                continue
            elif isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                _bad(f.name, f"must be a finite number (got {v!r})")
            elif v <= 0:
                _bad(f.name, f"must be > 0 (got {v})")
        self._check_layout()

    def _check_layout(self) -> None:
        p = self
        if p.disc_inner_radius >= p.disc_outer_radius:
            _bad("disc_inner_radius", f"must be < disc_outer_radius (got {p.disc_inner_radius})")
        if p.hat_wall_inner_radius <= p.bolt_face_outer_radius:
            _bad("hat_wall_thickness", "hat wall must lie outside the bolt face (disc_inner_radius - "
                 f"hat_wall_thickness = {p.hat_wall_inner_radius:.6g} <= bolt_face_outer_radius)")
        if p.flange_inner_radius >= p.bolt_face_outer_radius:
            _bad("flange_inner_radius", f"must be < bolt_face_outer_radius (got {p.flange_inner_radius})")
        if p.hat_depth <= p.flange_thickness:
            _bad("hat_depth", f"must be > flange_thickness (got {p.hat_depth} <= {p.flange_thickness})")
        if p.lining_inner_radius < p.disc_inner_radius:
            _bad("lining_inner_radius", f"must be >= disc_inner_radius (got {p.lining_inner_radius})")
        if p.lining_outer_radius <= p.lining_inner_radius:
            _bad("lining_outer_radius", f"must be > lining_inner_radius (got {p.lining_outer_radius})")
        if p.lining_outer_radius > p.disc_outer_radius:
            _bad("lining_outer_radius", f"must be <= disc_outer_radius (got {p.lining_outer_radius})")
        if p.lining_angle_deg >= 180:
            _bad("lining_angle_deg", f"must be < 180 (got {p.lining_angle_deg})")
        if not p.lining_angle_deg <= p.backplate_angle_deg < 180:
            _bad("backplate_angle_deg", f"must be in [lining_angle_deg, 180) (got {p.backplate_angle_deg})")
        if p.backplate_inner_radius <= p.disc_inner_radius:
            _bad("backplate_margin", "backplate would touch the hat (lining_inner_radius - backplate_margin "
                 f"= {p.backplate_inner_radius:.6g} <= disc_inner_radius)")
        clear = max(p.disc_outer_radius, p.backplate_outer_radius)
        if p.bridge_inner_x <= clear:
            _bad("bridge_thickness", f"bridge inner face x = caliper_outer_x - bridge_thickness = "
                 f"{p.bridge_inner_x:.6g} must clear the disc and backplates (r = {clear:.6g})")
        if p.housing_inner_x >= p.bridge_inner_x:
            _bad("housing_inner_x", f"must be < caliper_outer_x - bridge_thickness (got {p.housing_inner_x})")
        x_p, r_p = p.piston_radial_position, p.piston_radius
        if not (p.housing_inner_x < x_p - r_p and x_p + r_p < p.bridge_inner_x and r_p < p.caliper_half_width):
            _bad("piston_radius", f"piston bore (x = {x_p} +/- {r_p}) must lie inside the caliper housing, clear "
                 f"of the bridge (x < caliper_outer_x - bridge_thickness = {p.bridge_inner_x:.6g})")
        if p.piston_length <= p.caliper_gap:
            _bad("piston_length", f"must be > caliper_gap (got {p.piston_length})")
        if p.piston_length - p.caliper_gap >= p.housing_thickness:
            _bad("piston_length", "bore (piston_length - caliper_gap) must be shallower than housing_thickness")
        if p.finger_inner_x >= p.bridge_inner_x:
            _bad("finger_inner_x", f"must be < caliper_outer_x - bridge_thickness (got {p.finger_inner_x})")
        if p.finger_y_outer <= p.finger_y_inner:
            _bad("finger_y_outer", f"must be > finger_y_inner (got {p.finger_y_outer})")
        if p.finger_y_outer > p.caliper_half_width:
            _bad("finger_y_outer", f"must be <= caliper_half_width (got {p.finger_y_outer})")
        if p.finger_top_z > p.disc_thickness / 2 and p.backplate_back_z < p.z_top and \
                p.finger_inner_x <= p.disc_inner_radius:
            _bad("finger_inner_x", f"fingers would cut the hat: must be > disc_inner_radius "
                 f"(got {p.finger_inner_x})")
        if not (p.housing_inner_x <= p.ear_x - p.ear_width / 2 and p.ear_x + p.ear_width / 2 <= p.caliper_outer_x):
            _bad("ear_x", f"ears (x = {p.ear_x} +/- {p.ear_width / 2}) must lie within the housing's x range")
        if p.guide_hole_radius >= min(p.ear_width, p.ear_length) / 2:
            _bad("guide_hole_radius", f"must be < min(ear_width, ear_length) / 2 (got {p.guide_hole_radius})")

    # ---- derived positions -------------------------------------------------------------------
    @property
    def z_top(self) -> float:
        """z of the outboard (bolt) face of the hat flange."""
        return self.disc_thickness / 2 + self.hat_depth

    @property
    def hat_wall_inner_radius(self) -> float:
        return self.disc_inner_radius - self.hat_wall_thickness

    @property
    def backplate_inner_radius(self) -> float:
        return self.lining_inner_radius - self.backplate_margin

    @property
    def backplate_outer_radius(self) -> float:
        return self.lining_outer_radius + self.backplate_margin

    @property
    def backplate_back_z(self) -> float:
        """|z| of the backplate back faces (piston front, finger front)."""
        return self.disc_thickness / 2 + self.lining_thickness + self.backplate_thickness

    @property
    def housing_front_z(self) -> float:
        """z (< 0) of the housing front face."""
        return -(self.backplate_back_z + self.caliper_gap)

    @property
    def housing_back_z(self) -> float:
        return self.housing_front_z - self.housing_thickness

    @property
    def bore_bottom_z(self) -> float:
        """z (< 0) of the bore bottom = piston back face."""
        return -(self.backplate_back_z + self.piston_length)

    @property
    def bridge_inner_x(self) -> float:
        return self.caliper_outer_x - self.bridge_thickness

    @property
    def finger_top_z(self) -> float:
        return self.backplate_back_z + self.finger_thickness

    @property
    def guide_y(self) -> float:
        """|y| of the guide-pin axes."""
        return self.caliper_half_width + self.ear_length / 2

    def sizes(self) -> dict[str, float]:
        """Resolved mesh sizes of the disc, the pads (linings + backplates) and caliper + piston."""
        disc = self.disc_mesh_size or self.mesh_size
        return {"disc": disc, "pad": self.pad_mesh_size or min(self.mesh_size, disc),
                "caliper": self.caliper_mesh_size or self.mesh_size}

    def analytic_volumes(self) -> dict[str, float]:
        """Exact volume of each part (cell-tag name -> m³), for verification."""
        p, pi = self, math.pi
        h, ri, ro = p.disc_thickness, p.disc_inner_radius, p.disc_outer_radius
        wall_len = p.z_top - p.flange_thickness + h / 2
        disc = (pi * (ro**2 - ri**2) * h + pi * (ri**2 - p.hat_wall_inner_radius**2) * wall_len
                + pi * (ri**2 - p.flange_inner_radius**2) * p.flange_thickness)
        lining = math.radians(p.lining_angle_deg) / 2 * (p.lining_outer_radius**2 - p.lining_inner_radius**2) \
            * p.lining_thickness
        backplate = math.radians(p.backplate_angle_deg) / 2 \
            * (p.backplate_outer_radius**2 - p.backplate_inner_radius**2) * p.backplate_thickness
        w2 = 2 * p.caliper_half_width
        caliper = ((p.caliper_outer_x - p.housing_inner_x) * w2 * p.housing_thickness
                   + p.bridge_thickness * w2 * (p.finger_top_z - p.housing_front_z)
                   + 2 * (p.bridge_inner_x - p.finger_inner_x) * (p.finger_y_outer - p.finger_y_inner)
                   * p.finger_thickness
                   + 2 * (p.ear_width * p.ear_length - pi * p.guide_hole_radius**2) * p.housing_thickness
                   - pi * p.piston_radius**2 * (p.piston_length - p.caliper_gap))
        return {"disc": disc, "lining_inner": lining, "lining_outer": lining, "backplate_inner": backplate,
                "backplate_outer": backplate, "piston": pi * p.piston_radius**2 * p.piston_length,
                "caliper": caliper}


def _bad(field: str, reason: str):
    raise ValueError(f"geometry.{field}: {reason}")


# ---- OCC helpers ---------------------------------------------------------------------------------
def _sector_surface(occ, r_in: float, r_out: float, angle_deg: float, z: float) -> int:
    """Plane annular sector r_in <= r <= r_out, |θ| <= angle/2 at height z; returns the surface tag.

    Built at z = 0 and translated, so that the plane (and every mesh node on it) has z exactly.
    """
    a = math.radians(angle_deg) / 2
    c = occ.addPoint(0, 0, 0)
    p = [occ.addPoint(r * math.cos(t), r * math.sin(t), 0)
         for r, t in ((r_in, -a), (r_out, -a), (r_out, a), (r_in, a))]
    curves = [occ.addLine(p[0], p[1]), occ.addCircleArc(p[1], c, p[2]),
              occ.addLine(p[2], p[3]), occ.addCircleArc(p[3], c, p[0])]
    occ.remove([(0, c)])
    s = occ.addPlaneSurface([occ.addCurveLoop(curves)])
    occ.translate([(2, s)], 0, 0, z)
    return s


def _sector_volume(occ, r_in: float, r_out: float, angle_deg: float, z: float, dz: float) -> int:
    """Annular sector extruded from height z by dz (sign = direction); returns the volume tag."""
    s = _sector_surface(occ, r_in, r_out, angle_deg, z)
    return next(t for d, t in occ.extrude([(2, s)], 0, 0, dz) if d == 3)


def _annulus(occ, r_in: float, r_out: float, z0: float, dz: float) -> int:
    """Full annulus r_in <= r <= r_out between z0 and z0 + dz; returns the volume tag."""
    outer = occ.addCylinder(0, 0, z0, 0, 0, dz, r_out)
    inner = occ.addCylinder(0, 0, z0, 0, 0, dz, r_in)
    (vol,), _ = occ.cut([(3, outer)], [(3, inner)])
    return vol[1]


def _faces(model, vols: list[int]) -> list[int]:
    return sorted({t for d, t in model.getBoundary([(3, v) for v in vols], oriented=False) if d == 2})


def _axis_distance(model, tag: int, cx: float, cy: float) -> float:
    """Distance from the axis (cx, cy, z) of a point in the middle of a face's parametric domain."""
    lo, hi = model.getParametrizationBounds(2, tag)
    x, y, _ = model.getValue(2, tag, [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])])
    return math.hypot(x - cx, y - cy)


def _near(a: float, b: float, tol: float = 1e-7) -> bool:
    return abs(a - b) < tol


# ---- builder -------------------------------------------------------------------------------------
def build_brake_corner(model, p: BrakeCornerParams) -> None:
    """Add the brake corner to ``model`` (OCC) with its physical groups and mesh sizes.

    Flat faces are identified by the centre of mass, cylindrical faces by the distance of a point
    on them from their axis; each face is looked up only among the faces of its own part.
    """
    import gmsh  # heavy: gmsh (not needed to read mesh files)

    occ = model.occ
    h = p.disc_thickness
    # disc: ring + hat wall + two flange annuli, plus (matching) the lining footprints to imprint
    ring = _annulus(occ, p.disc_inner_radius, p.disc_outer_radius, -h / 2, h)
    wall_top = p.z_top - p.flange_thickness
    wall = _annulus(occ, p.hat_wall_inner_radius, p.disc_inner_radius, -h / 2, wall_top + h / 2)
    flange_bolt = _annulus(occ, p.flange_inner_radius, p.bolt_face_outer_radius, p.z_top, -p.flange_thickness)
    flange_rim = _annulus(occ, p.bolt_face_outer_radius, p.disc_inner_radius, p.z_top, -p.flange_thickness)
    tools = [(3, wall), (3, flange_bolt), (3, flange_rim)]
    # seams of the disc circles to θ = 180°, away from the pads (else a seam vertex splits the footprint)
    occ.rotate([(3, ring)] + tools, 0, 0, 0, 0, 0, 1, math.pi)
    if p.matching:
        tools += [(2, _sector_surface(occ, p.lining_inner_radius, p.lining_outer_radius, p.lining_angle_deg, z))
                  for z in (-h / 2, h / 2)]
    _, out = occ.fragment([(3, ring)], tools)
    ring_vols = [t for d, t in out[0] if d == 3]
    bolt_vols = [t for d, t in out[2] if d == 3]
    disc_vols = sorted({t for m in out for d, t in m if d == 3})
    patches = [[t for d, t in m if d == 2] for m in out[4:]]
    if p.matching and (any(len(s) != 1 for s in patches) or len(disc_vols) != 4):
        raise RuntimeError(f"brake corner: imprint of the lining footprint failed ({patches}, {disc_vols})")

    # pads: lining bonded to its backplate (fragment), separate from the disc
    pads = {}
    for side, sgn in (("inner", -1.0), ("outer", 1.0)):
        lining = _sector_volume(occ, p.lining_inner_radius, p.lining_outer_radius, p.lining_angle_deg,
                                sgn * h / 2, sgn * p.lining_thickness)
        plate = _sector_volume(occ, p.backplate_inner_radius, p.backplate_outer_radius, p.backplate_angle_deg,
                               sgn * (h / 2 + p.lining_thickness), sgn * p.backplate_thickness)
        _, out = occ.fragment([(3, lining)], [(3, plate)])
        pads[side] = ([t for d, t in out[0] if d == 3], [t for d, t in out[1] if d == 3])

    # piston: in the bore, front on the inner backplate back face
    piston = occ.addCylinder(p.piston_radial_position, 0, p.bore_bottom_z, 0, 0, p.piston_length, p.piston_radius)

    # caliper: boxes fused, then bore and guide holes cut
    x0, x1, w = p.housing_inner_x, p.caliper_outer_x, p.caliper_half_width
    z_b, z_f, t_h = p.housing_back_z, p.housing_front_z, p.housing_thickness
    boxes = [occ.addBox(p.bridge_inner_x, -w, z_b, p.bridge_thickness, 2 * w, p.finger_top_z - z_b)]
    for y0 in (-p.finger_y_outer, p.finger_y_inner):
        boxes.append(occ.addBox(p.finger_inner_x, y0, p.backplate_back_z, x1 - p.finger_inner_x,
                                p.finger_y_outer - p.finger_y_inner, p.finger_thickness))
    for y0 in (-w - p.ear_length, w):
        boxes.append(occ.addBox(p.ear_x - p.ear_width / 2, y0, z_b, p.ear_width, p.ear_length, t_h))
    housing = occ.addBox(x0, -w, z_b, x1 - x0, 2 * w, t_h)
    fused, _ = occ.fuse([(3, housing)], [(3, b) for b in boxes])
    pad_z = 0.5 * t_h   # cutting tools overshoot the faces they open
    cutters = [(3, occ.addCylinder(p.piston_radial_position, 0, p.bore_bottom_z, 0, 0,
                                   z_f - p.bore_bottom_z + pad_z, p.piston_radius))]
    cutters += [(3, occ.addCylinder(p.ear_x, y, z_b - pad_z, 0, 0, t_h + 2 * pad_z, p.guide_hole_radius))
                for y in (-p.guide_y, p.guide_y)]
    caliper, _ = occ.cut(fused, cutters)
    if len(caliper) != 1:
        raise RuntimeError(f"brake corner: caliper is not one volume ({caliper})")
    caliper = caliper[0][1]
    occ.synchronize()

    # ---- faces
    com = {}

    def c(t: int) -> tuple[float, float, float]:
        if t not in com:
            com[t] = occ.getCenterOfMass(2, t)
        return com[t]

    def planes_at(vols: list[int], z: float) -> list[int]:
        return [t for t in _faces(model, vols) if model.getType(2, t) == "Plane" and _near(c(t)[2], z)]

    def cylinders(vols: list[int], cx: float, cy: float, r: float) -> list[int]:
        return [t for t in _faces(model, vols) if model.getType(2, t) == "Cylinder"
                and _near(_axis_distance(model, t, cx, cy), r)]

    bb = p.backplate_back_z
    inner_plate, outer_plate = pads["inner"][1], pads["outer"][1]
    abut = [t for t in _faces(model, inner_plate + outer_plate) if model.getType(2, t) == "Plane"
            and not _near(abs(c(t)[2]), bb) and not _near(abs(c(t)[2]), bb - p.backplate_thickness)]
    guide = [t for y in (-p.guide_y, p.guide_y) for t in cylinders([caliper], p.ear_x, y, p.guide_hole_radius)]
    faces = {
        "disc_bolt_face": planes_at(bolt_vols, p.z_top),
        "disc_friction_inner": planes_at(ring_vols, -h / 2),
        "disc_friction_outer": planes_at(ring_vols, h / 2),
        "lining_inner_contact": planes_at(pads["inner"][0], -h / 2),
        "lining_outer_contact": planes_at(pads["outer"][0], h / 2),
        "piston_front": planes_at([piston], -bb),
        "backplate_inner_back": planes_at(inner_plate, -bb),
        "finger_front": planes_at([caliper], bb),
        "backplate_outer_back": planes_at(outer_plate, bb),
        "piston_back": planes_at([piston], p.bore_bottom_z),
        "bore_bottom": planes_at([caliper], p.bore_bottom_z),
        "piston_side": cylinders([piston], p.piston_radial_position, 0.0, p.piston_radius),
        "bore_wall": cylinders([caliper], p.piston_radial_position, 0.0, p.piston_radius),
        "caliper_guide": guide,
        "backplate_abutment": abut,
    }
    expected = {"finger_front": 2, "caliper_guide": 2, "backplate_abutment": 4, "lining_inner_contact": 1,
                "lining_outer_contact": 1, "disc_bolt_face": 1}
    for name, tag in BRAKE_CORNER_FACES.items():
        tags = faces[name]
        if not tags or len(tags) != expected.get(name, len(tags)):
            raise RuntimeError(f"brake corner: face {name!r} not identified (got surfaces {tags})")
        model.addPhysicalGroup(2, tags, tag)
        model.setPhysicalName(2, tag, name)
    volumes = {"disc": disc_vols, "lining_inner": pads["inner"][0], "lining_outer": pads["outer"][0],
               "backplate_inner": inner_plate, "backplate_outer": outer_plate, "piston": [piston],
               "caliper": [caliper]}
    for name, tag in BRAKE_CORNER_VOLUMES.items():
        model.addPhysicalGroup(3, volumes[name], tag)
        model.setPhysicalName(3, tag, name)

    # ---- matching: lining contact faces are periodic copies (identity) of the disc patches
    if p.matching:
        for patch, name in zip(patches, ("lining_inner_contact", "lining_outer_contact")):
            model.mesh.setPeriodic(2, faces[name], patch, _IDENTITY)

    # ---- mesh sizes: constant per part, prescribed on every point of the part
    sizes = p.sizes()
    size_of = {"disc": sizes["disc"], "lining_inner": sizes["pad"], "lining_outer": sizes["pad"],
               "backplate_inner": sizes["pad"], "backplate_outer": sizes["pad"], "piston": sizes["caliper"],
               "caliper": sizes["caliper"]}
    for name, vols in volumes.items():
        pts = model.getBoundary([(3, v) for v in vols], combined=False, oriented=False, recursive=True)
        model.mesh.setSize(sorted(set(pts)), size_of[name])
    # small holes: at least _CIRCLE_SEGMENTS elements round the circumference (curved P2 stays valid)
    hole = min(sizes["caliper"], 2 * math.pi * p.guide_hole_radius / _CIRCLE_SEGMENTS)
    pts = model.getBoundary([(2, t) for t in guide], combined=False, oriented=False, recursive=True)
    model.mesh.setSize(sorted(set(pts)), hole)
    # hat centre bore: about 2 elements through the flange there (fewer boundary-capping tetrahedra that
    # curving would invert); a Threshold field grades back to the part sizes over 2 x flange_thickness
    bore = [t for t in _faces(model, bolt_vols) if model.getType(2, t) == "Cylinder"
            and _near(_axis_distance(model, t, 0.0, 0.0), p.flange_inner_radius)]
    bore_size = min(sizes["disc"], _BORE_SIZE * p.flange_thickness)
    field = model.mesh.field
    dist = field.add("Distance")
    field.setNumbers(dist, "FacesList", bore)
    grade = field.add("Threshold")
    for name, value in (("IField", dist), ("LcMin", bore_size), ("LcMax", max(sizes.values())),
                        ("DistMin", 0.0), ("DistMax", 2 * p.flange_thickness)):
        field.setNumber(grade, name, value)
    field.setAsBackgroundMesh(grade)
    gmsh.option.setNumber("Mesh.MeshSizeMax", max(sizes.values()))
    gmsh.option.setNumber("Mesh.MeshSizeMin", 0.25 * min(hole, bore_size, *sizes.values()))
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 1)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 1)
    gmsh.option.setNumber("Mesh.Algorithm3D", _ATTEMPTS[0][0])
    gmsh.option.setNumber("Mesh.RandomSeed", _ATTEMPTS[0][1])


def _generate(model, order: int) -> None:
    """Mesh with the first of ``_ATTEMPTS`` that meshes everything and, for ``order=2``, gives curved
    tetrahedra with min SICN >= ``_MIN_SICN``; otherwise warn and keep the best attempt
    (:func:`geometry.gmsh_io.search_meshes`).

    The mesh is left at order 1: :func:`geometry.gmsh_io.to_dolfinx` then calls ``generate(3)``
    (a no-op, see :func:`geometry.gmsh_io.mesh_with`) and ``setOrder(2)``, which reproduces the
    checked second-order mesh."""

    accepted, quality = search_meshes(model, _ATTEMPTS, order, judge=order == 2)
    if accepted is not None:
        return
    if not quality:
        raise RuntimeError(f"brake corner: meshing failed with every (Algorithm3D, RandomSeed) in {_ATTEMPTS}")
    warnings.warn(f"brake corner: curved mesh has min SICN {max(quality.values()):.3g} < {_MIN_SICN} (best of "
                  f"(Algorithm3D, RandomSeed) -> SICN {quality}); try a slightly different mesh size",
                  RuntimeWarning, stacklevel=2)


def brake_corner_model(*, order: int = 2, **params) -> GmshModel:
    """The brake corner as a gmsh model to build; ``params`` are the fields of :class:`BrakeCornerParams`."""
    known = {f.name for f in dataclasses.fields(BrakeCornerParams)}
    for name in params:
        if name not in known:
            _bad(name, f"unknown parameter of builder 'brake_corner'; allowed: {sorted(known)}")
    p = BrakeCornerParams(**params)

    def build(model) -> None:
        build_brake_corner(model, p)
        _generate(model, order)

    return GmshModel(build, order, dict(BRAKE_CORNER_VOLUMES), dict(BRAKE_CORNER_FACES))


def brake_corner_mesh(comm: MPI.Comm, **params) -> MeshData:
    """Distributed brake-corner mesh; ``params`` as :func:`brake_corner_model`."""
    return to_dolfinx(comm, brake_corner_model(**params))
