//! OpenFOAM: a polyMesh of the lumen with a runnable laminar blood-flow case (`openfoam/`), and
//! lumen + wall in one polyMesh for fluid-solid region splitting (`openfoam-fsi/`).
//!
//! # polyMesh
//! Points are in metres whatever the mesh unit. Faces come from the canonical hex face table
//! [`HEX_FACES`] (outward winding): a face shared by two cells is internal, its owner is the
//! lower-numbered cell and it keeps the owner's outward winding, so its normal points from owner
//! to neighbour; internal faces are sorted by (owner, neighbour) (upper-triangular order). The
//! boundary faces follow patch by patch, each with its cell's outward winding, in the order of
//! the mesh's face sets:
//! * `openfoam`: `inlet`, one patch per outlet named as the mesh end (`outlet`, `outlet_1`, ...),
//!   all type `patch`, then `wall` (type `wall`, the lumen faces on the vessel wall); cellZone
//!   `lumen`;
//! * `openfoam-fsi`: the same `inlet`/outlet patches (lumen), then `wall_inlet`, `wall_outlet`, ...
//!   (the end rings of the wall) and `wall_outer` (the adventitial surface), all type `patch`;
//!   cellZones `lumen`, `intima`, `media`, `adventitia` and the faceZone `lumen_wall` of the
//!   internal lumen-wall interface faces (flipMap 0: normals point from the lumen into the wall).
//!   `constant/polyMesh/fluidSolidZones` holds the cellZones `fluid` and `solid` for
//!   `splitMeshRegions -cellZonesFileOnly fluidSolidZones` (two regions, interface patches
//!   `fluid_to_solid` / `solid_to_fluid`); `splitMeshRegions -cellZones` gives one region per layer.
//!
//! Every boundary face belongs to exactly one patch, or the writer fails and names the face.
//! ASCII by default; binary (`openfoam.binary`) writes points, faces (`faceCompactList`), owner and
//! neighbour as little-endian 32-bit labels and 64-bit scalars; boundary and zones stay ASCII.
//! Floats are written in Rust's shortest round-trip form, so reading them back gives the same
//! bits, and the output is byte-identical for the same mesh.
//!
//! # Case
//! From `templates/openfoam/` (embedded), placeholders `{{name}}` substituted strictly (an
//! unknown placeholder is an error): `system/{controlDict,fvSchemes,fvSolution}`, `0/U`, `0/p`,
//! `constant/transportProperties` (Newtonian blood, nu = 3.5e-6 m2/s by default),
//! `constant/turbulenceProperties` (laminar; v1912 reads this name), `system/decomposeParDict`
//! (method `simple`, slabs across the lumen's longest extent: Debian's v1912 has no Scotch) and
//! `Allrun` (`./Allrun N` runs on N MPI processes: decomposePar, the solver under mpirun,
//! reconstructPar). The inlet
//! velocity is written per inlet face ([`inlet_velocities`]): parabolic in the distance to the
//! section boundary, or plug, scaled so that the inlet flux is exactly the flow rate asked
//! ([`inlet_flow_rates`]: per inlet, `inlet_flow_rates_ml_s`, else its share by area of
//! `flow_rate_ml_s`, else `mean_velocity` times its area).
//! Every end of the mesh is its own patch with its own entry in `0/U` and `0/p` ([`EndNames`]):
//! the inlets (`inlet`, or `inlet_1`, `inlet_2`, ... of a vessel fed through several ends, or
//! their caps' names), each rendered from `templates/openfoam/0/{U,p}.inlet`, then each outlet
//! (`outlet`, or `outlet_1`, `outlet_2`, ... of a branched vessel), each rendered from
//! `templates/openfoam/0/{U,p}.outlet`: zero-gradient velocity, pressure 0. Wall: no-slip.
//!
//! A patch named `wall` of type `wall` makes OpenFOAM v1912 print a harmless "Removed patchGroup
//! 'wall' which clashes with patch 2 of the same name" warning (the type puts every wall patch in
//! the group `wall`); the name is kept because users and the issue expect it.

use super::text::{write_binary, write_items, Text};
use super::{write_atomic, WriteOptions};
use crate::data::config::{FoamSolver, InletProfile, OpenFoamConfig};
use crate::data::error::{Error, Result};
use crate::geometry::mesh::{
    closest_on_segment, face_nodes, quad_area_vector, sets, ElementFace, Region, VesselMesh, HEX_FACES,
};
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use std::io::Write;
use std::ops::Range;
use std::path::{Path, PathBuf};

/// Mesh lengths are mm; OpenFOAM points are metres.
const MM_TO_M: f64 = 1e-3;
/// Name of the interface faceZone in the FSI mesh.
pub const INTERFACE_ZONE: &str = "lumen_wall";

/// OpenFOAM patch type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PatchKind {
    Patch,
    Wall,
}

impl PatchKind {
    pub fn word(self) -> &'static str {
        match self {
            PatchKind::Patch => "patch",
            PatchKind::Wall => "wall",
        }
    }
}

/// One entry of `boundary`: faces `start..start + size`.
#[derive(Debug, Clone, PartialEq)]
pub struct Patch {
    pub name: String,
    pub kind: PatchKind,
    pub start: usize,
    pub size: usize,
}

impl Patch {
    pub fn range(&self) -> Range<usize> {
        self.start..self.start + self.size
    }
}

/// A faceZone: face labels (ascending) and per face whether its normal is flipped with respect
/// to the zone's direction (lumen -> wall).
#[derive(Debug, Clone, PartialEq)]
pub struct FaceZone {
    pub name: String,
    pub faces: Vec<u32>,
    pub flip: Vec<bool>,
}

/// An OpenFOAM polyMesh of quadrilateral faces, in metres.
#[derive(Debug, Clone, PartialEq)]
pub struct PolyMesh {
    pub points: Vec<Point3<f64>>,
    pub faces: Vec<[u32; 4]>,
    pub owner: Vec<u32>,
    pub neighbour: Vec<u32>,
    pub patches: Vec<Patch>,
    pub cell_zones: Vec<(String, Vec<u32>)>,
    pub face_zones: Vec<FaceZone>,
    pub n_cells: usize,
}

impl PolyMesh {
    pub fn n_internal(&self) -> usize {
        self.neighbour.len()
    }
    pub fn patch(&self, name: &str) -> Option<&Patch> {
        self.patches.iter().find(|p| p.name == name)
    }
    fn face_points(&self, f: usize) -> [Point3<f64>; 4] {
        self.faces[f].map(|p| self.points[p as usize])
    }
    /// Area vector (right-hand-rule normal times area).
    pub fn face_area(&self, f: usize) -> Vector3<f64> {
        quad_area_vector(self.face_points(f))
    }
    pub fn face_centre(&self, f: usize) -> Point3<f64> {
        let p = self.face_points(f);
        Point3::from((p[0].coords + p[1].coords + p[2].coords + p[3].coords) / 4.0)
    }
    /// Cell centres as the mean of their face centres (= the corner mean for a hexahedron).
    pub fn cell_centres(&self) -> Vec<Point3<f64>> {
        let mut sum = vec![Vector3::zeros(); self.n_cells];
        let mut count = vec![0usize; self.n_cells];
        for f in 0..self.faces.len() {
            let c = self.face_centre(f).coords;
            sum[self.owner[f] as usize] += c;
            count[self.owner[f] as usize] += 1;
            if f < self.n_internal() {
                sum[self.neighbour[f] as usize] += c;
                count[self.neighbour[f] as usize] += 1;
            }
        }
        sum.iter().zip(&count).map(|(s, &n)| Point3::from(s / n.max(1) as f64)).collect()
    }
    /// Volume enclosed by the boundary (divergence theorem).
    pub fn volume(&self) -> f64 {
        (self.n_internal()..self.faces.len()).map(|f| self.face_centre(f).coords.dot(&self.face_area(f))).sum::<f64>()
            / 3.0
    }

    /// The rules OpenFOAM relies on, including those checkMesh does not check: sizes, owner <
    /// neighbour, upper-triangular order, patches contiguous from nInternalFaces and covering all
    /// boundary faces, no face listed twice, six faces per cell, every point used, internal
    /// normals owner -> neighbour, boundary normals away from the owner cell's centre.
    /// Returns the list of violations (empty when the mesh is right).
    pub fn verify(&self) -> Vec<String> {
        let mut errors = Vec::new();
        let nf = self.faces.len();
        let ni = self.n_internal();
        if self.owner.len() != nf {
            errors.push(format!("owner has {} entries for {nf} faces", self.owner.len()));
            return errors;
        }
        for f in 0..ni {
            let (o, n) = (self.owner[f], self.neighbour[f]);
            if o >= n {
                errors.push(format!("internal face {f}: owner {o} >= neighbour {n}"));
            }
            if f > 0 && (self.owner[f - 1], self.neighbour[f - 1]) >= (o, n) {
                errors.push(format!("internal face {f}: not in upper-triangular order"));
            }
        }
        let mut next = ni;
        for p in &self.patches {
            if p.start != next {
                errors.push(format!("patch {} starts at {} instead of {next}", p.name, p.start));
            }
            next = p.start + p.size;
        }
        if next != nf {
            errors.push(format!("patches end at face {next}, the mesh has {nf} faces"));
        }
        let mut keys: Vec<([u32; 4], usize)> = self
            .faces
            .iter()
            .enumerate()
            .map(|(i, f)| {
                let mut k = *f;
                k.sort_unstable();
                (k, i)
            })
            .collect();
        keys.sort_unstable();
        for w in keys.windows(2) {
            if w[0].0 == w[1].0 {
                errors.push(format!("faces {} and {} have the same points", w[0].1, w[1].1));
            }
        }
        let mut per_cell = vec![0usize; self.n_cells];
        for f in 0..nf {
            per_cell[self.owner[f] as usize] += 1;
            if f < ni {
                per_cell[self.neighbour[f] as usize] += 1;
            }
        }
        if let Some((c, n)) = per_cell.iter().enumerate().find(|(_, n)| **n != 6) {
            errors.push(format!("cell {c} has {n} faces"));
        }
        let mut used = vec![false; self.points.len()];
        self.faces.iter().flatten().for_each(|&p| used[p as usize] = true);
        if let Some(p) = used.iter().position(|u| !u) {
            errors.push(format!("point {p} is used by no face"));
        }
        let centres = self.cell_centres();
        for f in 0..nf {
            let s = self.face_area(f);
            let o = centres[self.owner[f] as usize];
            let away = if f < ni { centres[self.neighbour[f] as usize] - o } else { self.face_centre(f) - o };
            if s.dot(&away) <= 0.0 {
                let what = if f < ni { "does not point from owner to neighbour" } else { "points into its cell" };
                errors.push(format!("face {f}: normal {what}"));
            }
        }
        errors
    }
}

fn no_face_set(name: &str) -> Error {
    Error::Geometry(format!("OpenFOAM writer: the mesh has no face set '{name}' (not a mesh built by vesselhex?)"))
}

fn face_set<'a>(mesh: &'a VesselMesh, name: &str) -> Result<&'a [ElementFace]> {
    mesh.face_sets.get(name).map(|v| v.as_slice()).ok_or_else(|| no_face_set(name))
}

struct PatchSpec<'a> {
    name: String,
    kind: PatchKind,
    faces: &'a [ElementFace],
}

/// Slot marks of `build`: a cell face that is on the boundary, not yet in a patch.
const UNASSIGNED: u32 = u32::MAX;

/// The cells of `hexes` around each node, ascending: node n's are `around[first[n]..first[n + 1]]`.
fn cells_around_nodes(hexes: &[crate::geometry::mesh::Hex], n_nodes: usize) -> (Vec<u32>, Vec<u32>) {
    let mut first = vec![0u32; n_nodes + 1];
    for h in hexes {
        for &n in h {
            first[n as usize + 1] += 1;
        }
    }
    for i in 1..first.len() {
        first[i] += first[i - 1];
    }
    let mut fill = first.clone();
    let mut around = vec![0u32; hexes.len() * 8];
    for (c, h) in hexes.iter().enumerate() {
        for &n in h {
            around[fill[n as usize] as usize] = c as u32;
            fill[n as usize] += 1;
        }
    }
    (first, around)
}

/// [`face_partners`]: a cell face shared with no other cell.
const NO_PARTNER: u32 = u32::MAX;

/// For every face slot (cell * 6 + canonical face) of the elements `cells`, the slot of the other
/// cell's face on the same four nodes, or [`NO_PARTNER`]. The candidates are the cells on both
/// ends of a diagonal of the face (from a node-to-cell table, each node's cells ascending), so the
/// pairing costs a few comparisons per face and the memory of the table. A face on more than two
/// cells, or twice on one, is refused.
fn face_partners(mesh: &VesselMesh, cells: Range<usize>) -> Result<Vec<u32>> {
    let hexes = &mesh.hexes[cells.clone()];
    let (first, around) = cells_around_nodes(hexes, mesh.nodes.len());
    let key = |c: usize, f: usize| {
        let mut k = face_nodes(&hexes[c], f);
        k.sort_unstable();
        k
    };
    /// Marks of a slot whose face is shared by more than two cells or twice by one cell.
    const DEGENERATE: u32 = u32::MAX - 1;
    let mut partner = vec![NO_PARTNER; hexes.len() * 6];
    let cells_at = |n: u32| &around[first[n as usize] as usize..first[n as usize + 1] as usize];
    partner.par_chunks_mut(6).enumerate().for_each(|(c, out)| {
        let keys: [[u32; 4]; 6] = std::array::from_fn(|f| key(c, f));
        for (f, slot) in out.iter_mut().enumerate() {
            let k = keys[f];
            if (0..6).any(|g| g != f && keys[g] == k) {
                *slot = DEGENERATE;
                continue;
            }
            // Cells on both ends of a diagonal of the face: the face's cells, in a conformal mesh.
            let q = face_nodes(&hexes[c], f);
            let (a, b) = (cells_at(q[0]), cells_at(q[2]));
            let (mut i, mut j) = (0, 0);
            while i < a.len() && j < b.len() {
                if a[i] < b[j] {
                    i += 1;
                } else if a[i] > b[j] {
                    j += 1;
                } else {
                    let d = a[i] as usize;
                    if d != c {
                        if let Some(g) = face_on(&hexes[d], &q, &k) {
                            *slot = if *slot == NO_PARTNER { (d * 6 + g) as u32 } else { DEGENERATE };
                        }
                    }
                    i += 1;
                    j += 1;
                }
            }
        }
    });
    if let Some(a) = partner.iter().position(|&p| p == DEGENERATE) {
        return Err(Error::Geometry(format!(
            "OpenFOAM writer: face S{} of element {} is shared by more than two cells or twice by one cell \
             (degenerate mesh)",
            a % 6 + 1,
            cells.start + a / 6 + 1
        )));
    }
    Ok(partner)
}

/// The face of `hex` whose nodes are those of `q` (`key`: `q` sorted), found from the corners
/// of `hex` among `q` as a bit mask, compared with each face's corners: one pass over the corners
/// instead of sorting the nodes of all six faces. The faces of a degenerate element (a node
/// twice) are compared node by node, as the mask may then name the wrong one.
fn face_on(hex: &crate::geometry::mesh::Hex, q: &[u32; 4], key: &[u32; 4]) -> Option<usize> {
    let sorted = |g: usize| {
        let mut k = face_nodes(hex, g);
        k.sort_unstable();
        k
    };
    let mask = (0..8).filter(|&k| q.contains(&hex[k])).fold(0u8, |m, k| m | 1 << k);
    match HEX_FACES.iter().position(|f| f.iter().fold(0u8, |m, &k| m | 1 << k) == mask) {
        Some(g) if sorted(g) == *key => Some(g),
        // Fewer than four corners on the nodes of q: no face of hex is on them.
        _ if mask.count_ones() < 4 => None,
        _ => (0..6).find(|&g| sorted(g) == *key),
    }
}

/// Builds the polyMesh of the elements `cells` (contiguous) with the given patches.
fn build(
    mesh: &VesselMesh,
    cells: Range<usize>,
    specs: &[PatchSpec],
    interface: Option<&[ElementFace]>,
    zones: &[(String, Range<usize>)],
) -> Result<PolyMesh> {
    let first = cells.start;
    let n_cells = cells.len();
    if n_cells == 0 {
        return Err(Error::Geometry("OpenFOAM writer: the mesh has no lumen elements".into()));
    }
    let point_node = mesh.nodes_of(cells.clone());
    let mut node_point = vec![u32::MAX; mesh.nodes.len()];
    for (p, &n) in point_node.iter().enumerate() {
        node_point[n as usize] = p as u32;
    }
    let cell_face = |slot: usize| -> [u32; 4] {
        face_nodes(&mesh.hexes[first + slot / 6], slot % 6).map(|n| node_point[n as usize])
    };

    // Pair equal faces: each cell face finds its twin among the cells around its first node.
    let partner = face_partners(mesh, cells.clone())?;
    let upward = |a: usize| partner[a] != NO_PARTNER && partner[a] as usize / 6 > a / 6;
    let n_internal = (0..partner.len()).filter(|&a| upward(a)).count();
    let n_faces = n_internal + partner.iter().filter(|&&p| p == NO_PARTNER).count();
    let mut slot_face = vec![UNASSIGNED; n_cells * 6];
    let mut faces = Vec::with_capacity(n_faces);
    let mut owner = Vec::with_capacity(n_faces);
    let mut neighbour = Vec::with_capacity(n_internal);
    // Internal faces in (owner, neighbour) order, the owner the lower cell, its slot first among equals.
    for c in 0..n_cells {
        let mut up = [(0u32, 0usize); 6];
        let mut count = 0;
        for a in (c * 6..c * 6 + 6).filter(|&a| upward(a)) {
            up[count] = (partner[a] / 6, a);
            count += 1;
        }
        up[..count].sort_unstable();
        for &(n, a) in &up[..count] {
            let k = faces.len() as u32;
            faces.push(cell_face(a));
            owner.push(c as u32);
            neighbour.push(n);
            slot_face[a] = k;
            slot_face[partner[a] as usize] = k;
        }
    }
    drop(partner);
    // The points after the pairing's table is gone (the peak of the build is the pairing's, and
    // of the whole run at 0.8 M hexes); `+ 0.0` turns -0 into 0, so that files never show "-0e0".
    let points: Vec<Point3<f64>> =
        point_node.iter().map(|&n| (mesh.nodes[n as usize].coords * MM_TO_M).map(|x| x + 0.0).into()).collect();

    let slot_of = |set: &str, ef: &ElementFace| -> Result<usize> {
        let e = ef.element as usize;
        if !cells.contains(&e) || ef.face > 5 {
            return Err(Error::Geometry(format!(
                "OpenFOAM writer: face set '{set}' names face S{} of element {}, which is not in this mesh",
                ef.face + 1,
                e + 1
            )));
        }
        Ok((e - first) * 6 + ef.face as usize)
    };
    let mut patches = Vec::with_capacity(specs.len());
    for spec in specs {
        let start = faces.len();
        for ef in spec.faces {
            let slot = slot_of(&spec.name, ef)?;
            match slot_face[slot] {
                UNASSIGNED => {
                    slot_face[slot] = faces.len() as u32;
                    faces.push(cell_face(slot));
                    owner.push((slot / 6) as u32);
                }
                f if (f as usize) < n_internal => {
                    return Err(Error::Geometry(format!(
                        "OpenFOAM writer: patch '{}' lists face S{} of element {}, which is shared with another cell",
                        spec.name,
                        ef.face + 1,
                        ef.element + 1
                    )))
                }
                _ => {
                    return Err(Error::Geometry(format!(
                        "OpenFOAM writer: face S{} of element {} is in two patches (the second is '{}')",
                        ef.face + 1,
                        ef.element + 1,
                        spec.name
                    )))
                }
            }
        }
        patches.push(Patch { name: spec.name.clone(), kind: spec.kind, start, size: faces.len() - start });
    }
    let missing: Vec<usize> = (0..slot_face.len()).filter(|&s| slot_face[s] == UNASSIGNED).collect();
    if let Some(&s) = missing.first() {
        return Err(Error::Geometry(format!(
            "OpenFOAM writer: {} boundary faces are in no patch, the first is face S{} of element {}",
            missing.len(),
            s % 6 + 1,
            first + s / 6 + 1
        )));
    }

    let mut face_zones = Vec::new();
    if let Some(set) = interface {
        let mut zone: Vec<(u32, bool)> = Vec::with_capacity(set.len());
        for ef in set {
            let slot = slot_of(INTERFACE_ZONE, ef)?;
            let f = slot_face[slot];
            if f as usize >= n_internal {
                return Err(Error::Geometry(format!(
                    "OpenFOAM writer: interface face S{} of element {} is not shared with a wall element",
                    ef.face + 1,
                    ef.element + 1
                )));
            }
            // The set lists lumen faces (outward = into the wall): flipped when the owner is not the lumen cell.
            zone.push((f, owner[f as usize] as usize != slot / 6));
        }
        zone.sort_unstable();
        face_zones.push(FaceZone {
            name: INTERFACE_ZONE.into(),
            faces: zone.iter().map(|z| z.0).collect(),
            flip: zone.iter().map(|z| z.1).collect(),
        });
    }
    let cell_zones = zones
        .iter()
        .filter(|(_, r)| !r.is_empty())
        .map(|(name, r)| (name.clone(), ((r.start - first) as u32..(r.end - first) as u32).collect()))
        .collect();
    Ok(PolyMesh { points, faces, owner, neighbour, patches, cell_zones, face_zones, n_cells })
}

/// The end patches of the lumen, named as the mesh's ends: its inlets, then every outlet, each
/// in the mesh's order (`inlet`, or `inlet_1`, ...; `outlet`, or `outlet_1`, `outlet_2`, ... of
/// a branched vessel).
#[derive(Debug, Clone, PartialEq)]
pub struct EndNames {
    pub inlets: Vec<String>,
    pub outlets: Vec<String>,
}

impl EndNames {
    /// Fails unless the mesh has an inlet and an outlet (the case drives the flow in through the
    /// inlets and out through the outlets).
    pub fn of(mesh: &VesselMesh) -> Result<Self> {
        let inlets: Vec<String> = mesh.ends.iter().filter(|e| e.is_inlet).map(|e| e.name.clone()).collect();
        let outlets: Vec<String> = mesh.outlets().map(|e| e.name.clone()).collect();
        if inlets.is_empty() {
            return Err(Error::Geometry("OpenFOAM writer: the mesh has no inlet end".into()));
        }
        if outlets.is_empty() {
            return Err(Error::Geometry(format!(
                "OpenFOAM writer: the mesh has no outlet end (every end is an inlet: {}); the flow needs a way out: \
                 give fewer --inlet ends",
                inlets.join(", ")
            )));
        }
        Ok(EndNames { inlets, outlets })
    }
    /// The inlets, then the outlets.
    pub fn all(&self) -> impl Iterator<Item = &str> {
        self.inlets.iter().chain(&self.outlets).map(|s| s.as_str())
    }
}

/// Inlet patch then one patch per outlet, from the lumen end face sets.
fn end_patches<'a>(mesh: &'a VesselMesh, ends: &EndNames) -> Result<Vec<PatchSpec<'a>>> {
    let mut specs = Vec::new();
    for end in ends.all() {
        specs.push(PatchSpec {
            name: end.to_string(),
            kind: PatchKind::Patch,
            faces: face_set(mesh, &sets::lumen_end(end))?,
        });
    }
    Ok(specs)
}

/// The polyMesh of the fluid: patches inlet, outlets, wall; cellZone lumen. With flow
/// extensions (see [`crate::stages::additions::extensions`]), their cells follow the lumen's, in cellZone
/// `extension`, their rigid wall is the patch `extension_wall` (before `wall`) and the end
/// patches lie at the extended ends.
pub fn lumen_polymesh(mesh: &VesselMesh) -> Result<PolyMesh> {
    let fluid = crate::stages::additions::extensions::fluid_view(mesh);
    let mesh = &*fluid;
    let mut specs = end_patches(mesh, &EndNames::of(mesh)?)?;
    specs.extend(extension_wall_patch(mesh));
    specs.push(PatchSpec {
        name: "wall".into(),
        kind: PatchKind::Wall,
        faces: face_set(mesh, sets::LUMEN_WALL_FACES)?,
    });
    let (lumen, extension) = (mesh.lumen_range(), mesh.extension_range());
    let zones =
        [(Region::Lumen.name().to_string(), lumen.clone()), (Region::Extension.name().to_string(), extension.clone())];
    // The lumen then the extensions (after them in this view), whose range is empty without any.
    let end = if extension.is_empty() { lumen.end } else { extension.end };
    build(mesh, lumen.start..end, &specs, None, &zones)
}

/// The flow extensions' rigid wall, when the mesh has extensions.
fn extension_wall_patch(mesh: &VesselMesh) -> Option<PatchSpec<'_>> {
    mesh.face_sets.get(sets::EXTENSION_WALL).map(|faces| PatchSpec {
        name: sets::EXTENSION_WALL.into(),
        kind: PatchKind::Wall,
        faces,
    })
}

/// The polyMesh of lumen and wall: patches inlet, outlets, wall end rings, outer wall; cellZones
/// per region; faceZone of the lumen-wall interface.
pub fn fsi_polymesh(mesh: &VesselMesh) -> Result<PolyMesh> {
    let ends = EndNames::of(mesh)?;
    let mut specs = end_patches(mesh, &ends)?;
    for end in ends.all() {
        let name = sets::wall_end(end);
        specs.push(PatchSpec { faces: face_set(mesh, &name)?, name, kind: PatchKind::Patch });
    }
    specs.push(PatchSpec {
        name: sets::WALL_OUTER_FACES.into(),
        kind: PatchKind::Patch,
        faces: face_set(mesh, sets::WALL_OUTER_FACES)?,
    });
    specs.extend(extension_wall_patch(mesh));
    let zones: Vec<(String, Range<usize>)> =
        Region::ALL.iter().chain([&Region::Extension]).map(|r| (r.name().to_string(), mesh.region_range(*r))).collect();
    if mesh.wall_range().is_empty() {
        return Err(Error::Geometry("OpenFOAM writer (openfoam-fsi): the mesh has no wall elements".into()));
    }
    build(mesh, 0..mesh.hexes.len(), &specs, Some(face_set(mesh, sets::LUMEN_WALL_FACES)?), &zones)
}

// ---------------------------------------------------------------------------------------------
// Files

fn header(
    w: &mut dyn Write,
    binary: bool,
    class: &str,
    location: &str,
    object: &str,
    note: Option<&str>,
) -> std::io::Result<()> {
    writeln!(w, "/*--------------------------------*- C++ -*----------------------------------*\\")?;
    writeln!(w, "  Written by vesselhex {}", env!("CARGO_PKG_VERSION"))?;
    writeln!(w, "\\*---------------------------------------------------------------------------*/")?;
    writeln!(w, "FoamFile\n{{\n    version     2.0;")?;
    writeln!(w, "    format      {};", if binary { "binary" } else { "ascii" })?;
    if binary {
        writeln!(w, "    arch        \"LSB;label=32;scalar=64\";")?;
    }
    writeln!(w, "    class       {class};")?;
    if let Some(note) = note {
        writeln!(w, "    note        \"{note}\";")?;
    }
    writeln!(w, "    location    \"{location}\";\n    object      {object};\n}}")?;
    writeln!(w, "// * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * //\n")
}

/// A binary list of `n` items: `N\n(` raw bytes `)`; `encode(i, bytes)` appends item `i`.
fn binary_list(w: &mut dyn Write, n: usize, encode: impl Fn(usize, &mut Vec<u8>)) -> std::io::Result<()> {
    write!(w, "{n}\n(")?;
    write_binary(w, n, |range, bytes| range.for_each(|i| encode(i, bytes)))?;
    writeln!(w, ")")
}

/// A 32-bit label, little-endian.
fn label_bytes(x: u32, out: &mut Vec<u8>) {
    out.extend_from_slice(&(x as i32).to_le_bytes());
}

/// An ASCII list: `N\n(`, one item per line, `)`.
fn ascii_list(w: &mut dyn Write, n: usize, item: impl Fn(&mut Text, usize) + Sync) -> std::io::Result<()> {
    writeln!(w, "{n}\n(")?;
    write_items(w, n, |t, i| {
        item(t, i);
        t.byte(b'\n');
    })?;
    writeln!(w, ")")
}

fn write_labels(w: &mut dyn Write, binary: bool, v: &[u32]) -> std::io::Result<()> {
    if binary && !v.is_empty() {
        binary_list(w, v.len(), |i, out| label_bytes(v[i], out))
    } else {
        ascii_list(w, v.len(), |t, i| {
            t.uint(v[i] as u64);
        })
    }
}

/// A polyMesh file's writer.
type FileFn<'a> = Box<dyn Fn(&mut dyn Write) -> std::io::Result<()> + Sync + 'a>;

/// Writes `constant/polyMesh` under `case` and returns the paths written, relative to `case`.
pub fn write_polymesh(poly: &PolyMesh, binary: bool, case: &Path) -> Result<Vec<PathBuf>> {
    let rel = PathBuf::from("constant/polyMesh");
    let dir = case.join(&rel);
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, "cannot create the folder", e))?;
    let loc = "constant/polyMesh";
    let note = format!(
        "nPoints:{} nCells:{} nFaces:{} nInternalFaces:{}",
        poly.points.len(),
        poly.n_cells,
        poly.faces.len(),
        poly.n_internal()
    );
    let mut files: Vec<(&str, FileFn)> = vec![
        ("points", Box::new(|w| write_points(w, poly, binary, loc))),
        ("faces", Box::new(|w| write_faces(w, poly, binary, loc))),
        ("owner", Box::new(|w| write_label_file(w, binary, "owner", &note, &poly.owner))),
        ("neighbour", Box::new(|w| write_label_file(w, binary, "neighbour", &note, &poly.neighbour))),
        ("boundary", Box::new(|w| write_boundary(w, poly, loc))),
    ];
    if !poly.cell_zones.is_empty() {
        files.push(("cellZones", Box::new(|w| write_cell_zones(w, loc, "cellZones", &poly.cell_zones))));
    }
    if !poly.face_zones.is_empty() {
        files.push(("faceZones", Box::new(|w| write_face_zones(w, poly, loc))));
    }
    write_on_two_threads(&dir, &files)?;
    Ok(files.iter().map(|(name, _)| rel.join(name)).collect())
}

/// Writes `files` under `dir`: the first (the points, which take about as long as the others
/// together) on a thread of its own, the others in turn on this one. With two files at once one
/// file's serial part (the copies into the buffer, the waits on the disk, the sync) overlaps the
/// other's, and the lists of both format on every core. The error of the first file that failed.
fn write_on_two_threads(dir: &Path, files: &[(&str, FileFn)]) -> Result<()> {
    let write = |(name, f): &(&str, FileFn)| write_atomic(&dir.join(name), |w| f(w));
    let Some((first, rest)) = files.split_first() else { return Ok(()) };
    std::thread::scope(|s| {
        let first = s.spawn(|| write(first));
        let rest = rest.iter().try_for_each(write);
        first.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic)).and(rest)
    })
}

/// `owner` or `neighbour` (`object`), with the mesh's sizes in the header's note.
fn write_label_file(w: &mut dyn Write, binary: bool, object: &str, note: &str, v: &[u32]) -> std::io::Result<()> {
    header(w, binary, "labelList", "constant/polyMesh", object, Some(note))?;
    write_labels(w, binary, v)
}

fn write_points(w: &mut dyn Write, poly: &PolyMesh, binary: bool, loc: &str) -> std::io::Result<()> {
    header(w, binary, "vectorField", loc, "points", None)?;
    let points = &poly.points;
    if binary {
        binary_list(w, points.len(), |i, out| {
            [points[i].x, points[i].y, points[i].z].iter().for_each(|x| out.extend_from_slice(&x.to_le_bytes()))
        })
    } else {
        ascii_list(w, points.len(), |t, i| {
            let p = points[i];
            t.byte(b'(').exp(p.x).byte(b' ').exp(p.y).byte(b' ').exp(p.z).byte(b')');
        })
    }
}

fn write_faces(w: &mut dyn Write, poly: &PolyMesh, binary: bool, loc: &str) -> std::io::Result<()> {
    let faces = &poly.faces;
    if binary {
        header(w, true, "faceCompactList", loc, "faces", None)?;
        binary_list(w, faces.len() + 1, |i, out| label_bytes(4 * i as u32, out))?;
        writeln!(w)?;
        binary_list(w, 4 * faces.len(), |i, out| label_bytes(faces[i / 4][i % 4], out))
    } else {
        header(w, false, "faceList", loc, "faces", None)?;
        ascii_list(w, faces.len(), |t, i| {
            t.str("4(").uints(faces[i].map(u64::from), " ").byte(b')');
        })
    }
}

fn write_boundary(w: &mut dyn Write, poly: &PolyMesh, loc: &str) -> std::io::Result<()> {
    header(w, false, "polyBoundaryMesh", loc, "boundary", None)?;
    writeln!(w, "{}\n(", poly.patches.len())?;
    for p in &poly.patches {
        writeln!(w, "    {}\n    {{\n        type            {};", p.name, p.kind.word())?;
        if p.kind == PatchKind::Wall {
            writeln!(w, "        inGroups        1(wall);")?;
        }
        writeln!(w, "        nFaces          {};\n        startFace       {};\n    }}", p.size, p.start)?;
    }
    writeln!(w, ")")
}

fn write_face_zones(w: &mut dyn Write, poly: &PolyMesh, loc: &str) -> std::io::Result<()> {
    header(w, false, "regIOobject", loc, "faceZones", None)?;
    writeln!(w, "{}\n(", poly.face_zones.len())?;
    for z in &poly.face_zones {
        write!(w, "{}\n{{\n    type faceZone;\n    faceLabels List<label> ", z.name)?;
        ascii_list(w, z.faces.len(), |t, i| {
            t.uint(z.faces[i] as u64);
        })?;
        write!(w, ";\n    flipMap List<bool> ")?;
        ascii_list(w, z.flip.len(), |t, i| {
            t.byte(b'0' + z.flip[i] as u8);
        })?;
        writeln!(w, ";\n}}")?;
    }
    writeln!(w, ")")
}

fn write_cell_zones(
    w: &mut dyn Write,
    location: &str,
    object: &str,
    zones: &[(String, Vec<u32>)],
) -> std::io::Result<()> {
    header(w, false, "regIOobject", location, object, None)?;
    writeln!(w, "{}\n(", zones.len())?;
    for (name, cells) in zones {
        write!(w, "{name}\n{{\n    type cellZone;\n    cellLabels List<label> ")?;
        ascii_list(w, cells.len(), |t, i| {
            t.uint(cells[i] as u64);
        })?;
        writeln!(w, ";\n}}")?;
    }
    writeln!(w, ")")
}

// ---------------------------------------------------------------------------------------------
// Case

const TEMPLATES: &[(&str, &str)] = &[
    ("system/controlDict", include_str!("../../templates/openfoam/system/controlDict")),
    ("system/fvSchemes", include_str!("../../templates/openfoam/system/fvSchemes")),
    ("system/fvSolution", include_str!("../../templates/openfoam/system/fvSolution")),
    ("system/decomposeParDict", include_str!("../../templates/openfoam/system/decomposeParDict")),
    ("0/U", include_str!("../../templates/openfoam/0/U")),
    ("0/p", include_str!("../../templates/openfoam/0/p")),
    ("constant/transportProperties", include_str!("../../templates/openfoam/constant/transportProperties")),
    ("constant/turbulenceProperties", include_str!("../../templates/openfoam/constant/turbulenceProperties")),
    ("Allrun", include_str!("../../templates/openfoam/Allrun")),
];
const FSI_ALLRUN: &str = include_str!("../../templates/openfoam-fsi/Allrun");
/// Per-outlet entries of the field files: placeholder in the field file, and the piece rendered
/// once per outlet with `{{outlet}}` = the outlet's patch name.
const OUTLET_PIECES: &[(&str, &str, &str)] = &[
    ("outlets_U", "templates/openfoam/0/U.outlet", include_str!("../../templates/openfoam/0/U.outlet")),
    ("outlets_p", "templates/openfoam/0/p.outlet", include_str!("../../templates/openfoam/0/p.outlet")),
];
/// The per-inlet entry of `0/p`, `{{inlet}}` = the inlet's patch name.
const INLET_P: (&str, &str) = ("templates/openfoam/0/p.inlet", include_str!("../../templates/openfoam/0/p.inlet"));
/// The per-inlet entry of `0/U`, `{{inlet}}` = the inlet's patch name, `{{inlet_velocity}}` its
/// per-face velocities.
const INLET_U: (&str, &str) = ("templates/openfoam/0/U.inlet", include_str!("../../templates/openfoam/0/U.inlet"));

/// The end-patch values of the field templates: one entry per inlet in `0/p` (`inlets_p`; those
/// of `0/U` carry the inflow: [`InletFields`]) and one per outlet for each field (`outlets_U`,
/// `outlets_p`), so that each end has its own boundary condition.
pub fn end_vars(ends: &EndNames) -> Result<Vec<(&'static str, String)>> {
    let mut inlets_p = String::new();
    for inlet in &ends.inlets {
        inlets_p.push_str(&render(INLET_P.0, INLET_P.1, &[("inlet", inlet.clone())])?);
    }
    let mut vars = vec![("inlets_p", inlets_p)];
    for (key, label, piece) in OUTLET_PIECES {
        let mut text = String::new();
        for outlet in &ends.outlets {
            text.push_str(&render(label, piece, &[("outlet", outlet.clone())])?);
        }
        vars.push((*key, text));
    }
    Ok(vars)
}

pub use super::template::render;

/// The field entries of the flow extensions' wall patch (`extension_wall_U`, `extension_wall_p`,
/// `extension_wall_displacement` of the FSI overlay): empty without extensions.
pub fn extension_wall_vars(poly: &PolyMesh) -> Vec<(&'static str, String)> {
    EXTENSION_WALL_PIECES
        .iter()
        .map(|(key, piece)| {
            (*key, if poly.patch(sets::EXTENSION_WALL).is_some() { piece.to_string() } else { String::new() })
        })
        .collect()
}

/// The flow extensions' wall entries of the field files: placeholder and text.
const EXTENSION_WALL_PIECES: &[(&str, &str)] = &[
    ("extension_wall_U", include_str!("../../templates/openfoam/0/U.extension_wall")),
    ("extension_wall_p", include_str!("../../templates/openfoam/0/p.extension_wall")),
    ("extension_wall_displacement", include_str!("../../templates/fsi/openfoam/0/pointDisplacement.extension_wall")),
];

/// The inflow written to `0/U`.
#[derive(Debug, Clone, PartialEq)]
pub struct Inflow {
    /// Volume flow rate, m3/s (exactly the flux of `velocities` into the domain).
    pub flow_rate: f64,
    /// Inlet area, m2.
    pub area: f64,
    /// Velocity per inlet face, m/s (pointing into the domain).
    pub velocities: Vec<Vector3<f64>>,
}

/// Per-face inlet velocities. Parabolic: u = u0 rho (2 - rho), rho = d / d_max with d the
/// distance of the face centre to the boundary of the inlet section (its edges used by one
/// inlet face only) and d_max the largest such distance over face centres and points (on a circle
/// this is 1 - r^2/R^2). Plug: u = u0. u0 is set so that the flux through the faces is
/// `flow_rate` (m3/s).
pub fn inlet_velocities(poly: &PolyMesh, inlet: &Patch, profile: InletProfile, flow_rate: f64) -> Inflow {
    let faces = inlet.range();
    let areas: Vec<Vector3<f64>> = faces.clone().map(|f| poly.face_area(f)).collect();
    let area = patch_area(poly, inlet);
    let shape: Vec<f64> = match profile {
        InletProfile::Plug => vec![1.0; areas.len()],
        InletProfile::Parabolic => {
            let mut edges: Vec<(u32, u32)> = faces
                .clone()
                .flat_map(|f| {
                    let q = poly.faces[f];
                    (0..4).map(move |k| (q[k].min(q[(k + 1) % 4]), q[k].max(q[(k + 1) % 4])))
                })
                .collect();
            edges.sort_unstable();
            let mut rim = Vec::new();
            let mut i = 0;
            while i < edges.len() {
                let mut j = i + 1;
                while j < edges.len() && edges[j] == edges[i] {
                    j += 1;
                }
                if j - i == 1 {
                    rim.push(edges[i]);
                }
                i = j;
            }
            let dist = |p: &Point3<f64>| {
                rim.iter()
                    .map(|&(a, b)| {
                        (p - closest_on_segment(p, &poly.points[a as usize], &poly.points[b as usize])).norm()
                    })
                    .fold(f64::INFINITY, f64::min)
            };
            let d: Vec<f64> = faces.clone().map(|f| dist(&poly.face_centre(f))).collect();
            let d_points = faces.clone().flat_map(|f| poly.faces[f]).map(|p| dist(&poly.points[p as usize]));
            let d_max = d.iter().copied().chain(d_points).fold(0.0, f64::max);
            d.iter()
                .map(|&d| {
                    let rho = (d / d_max).min(1.0);
                    rho * (2.0 - rho)
                })
                .collect()
        }
    };
    let weighted: f64 = shape.iter().zip(&areas).map(|(s, a)| s * a.norm()).sum();
    let u0 = flow_rate / weighted;
    let velocities = areas.iter().zip(&shape).map(|(a, s)| (-a.normalize() * (u0 * s)).map(|x| x + 0.0)).collect();
    Inflow { flow_rate, area, velocities }
}

/// The area of a patch (m2 in a case written in metres).
fn patch_area(poly: &PolyMesh, patch: &Patch) -> f64 {
    patch.range().map(|f| poly.face_area(f).norm()).sum()
}

/// The flow rate of each inlet of `ends` (m3/s, in its order): its own
/// `inlet_flow_rates_ml_s`, else its share by area of `flow_rate_ml_s` among the inlets without
/// their own, else `mean_velocity` times its area. Fails on a rate given for an end that is no
/// inlet.
pub fn inlet_flow_rates(poly: &PolyMesh, ends: &EndNames, config: &OpenFoamConfig) -> Result<Vec<f64>> {
    if let Some(name) = config.inlet_flow_rates_ml_s.keys().find(|n| !ends.inlets.contains(n)) {
        return Err(Error::Config(format!(
            "openfoam.inlet_flow_rates_ml_s: the mesh has no inlet named {name} (its inlets: {}); name the inlets as \
             report.json does",
            ends.inlets.join(", ")
        )));
    }
    let areas = ends.inlets.iter().map(|name| inlet_patch(poly, name).map(|p| patch_area(poly, p)));
    let areas: Vec<f64> = areas.collect::<Result<_>>()?;
    let own = |name: &str| config.inlet_flow_rates_ml_s.get(name).map(|q| q * 1e-6);
    let shared_area: f64 = ends.inlets.iter().zip(&areas).filter(|(n, _)| own(n).is_none()).map(|(_, a)| a).sum();
    Ok(ends
        .inlets
        .iter()
        .zip(&areas)
        .map(|(name, &area)| {
            own(name)
                .or(config.flow_rate_ml_s.map(|q| q * 1e-6 * (area / shared_area)))
                .unwrap_or(config.mean_velocity * area)
        })
        .collect())
}

fn inlet_patch<'a>(poly: &'a PolyMesh, name: &str) -> Result<&'a Patch> {
    poly.patch(name).ok_or_else(|| Error::Geometry(format!("OpenFOAM writer: no inlet patch '{name}'")))
}

/// The inlets' part of `0/U`: an entry per inlet with its per-face velocities.
pub struct InletFields {
    /// The entries (`inlets_U`), rendered from `templates/openfoam/0/U.inlet`.
    pub entries: String,
    /// The inflow in words, for the file's header (`inflow`).
    pub summary: String,
    /// The flow rate through all the inlets, m3/s.
    pub flow_rate: f64,
    /// The largest inlet face speed, m/s.
    pub max_speed: f64,
}

/// Each inlet's velocities at its flow rate ([`inlet_flow_rates`], [`inlet_velocities`]).
pub fn inlet_fields(poly: &PolyMesh, ends: &EndNames, config: &OpenFoamConfig) -> Result<InletFields> {
    let rates = inlet_flow_rates(poly, ends, config)?;
    let profile = match config.profile {
        InletProfile::Parabolic => "parabolic",
        InletProfile::Plug => "plug",
    };
    let mut fields =
        InletFields { entries: String::new(), summary: format!("{profile} profile"), flow_rate: 0.0, max_speed: 0.0 };
    for (name, &rate) in ends.inlets.iter().zip(&rates) {
        let inflow = inlet_velocities(poly, inlet_patch(poly, name)?, config.profile, rate);
        let mut u = format!("nonuniform List<vector>\n{}\n(\n", inflow.velocities.len());
        for v in &inflow.velocities {
            u.push_str(&format!("({:e} {:e} {:e})\n", v.x, v.y, v.z));
        }
        u.push(')');
        fields.entries.push_str(&render(INLET_U.0, INLET_U.1, &[("inlet", name.clone()), ("inlet_velocity", u)])?);
        let figures = format!(
            "mean velocity {} m/s, flow rate {} m3/s",
            num(inflow.flow_rate / inflow.area),
            num(inflow.flow_rate)
        );
        let several = ends.inlets.len() > 1;
        fields.summary.push_str(&if several { format!("; {name}: {figures}") } else { format!(", {figures}") });
        fields.flow_rate += inflow.flow_rate;
        fields.max_speed = inflow.velocities.iter().map(|v| v.norm()).fold(fields.max_speed, f64::max);
    }
    Ok(fields)
}

fn num(x: f64) -> String {
    format!("{x:e}")
}

/// Shortest distance between the centres of two neighbouring cells.
fn min_centre_distance(poly: &PolyMesh) -> f64 {
    let c = poly.cell_centres();
    (0..poly.n_internal())
        .map(|f| (c[poly.neighbour[f] as usize] - c[poly.owner[f] as usize]).norm())
        .fold(f64::INFINITY, f64::min)
}

/// The axis of the lumen's longest extent (`x`, `y` or `z`) and the `n` of decomposePar's
/// `simple` method that cuts it into a given number of slabs: `(1 1 N)` along z, ...
pub fn slab_axis(poly: &PolyMesh) -> (&'static str, impl Fn(&str) -> String) {
    let extent = |k: usize| {
        let (lo, hi) = poly.points.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| (lo.min(p[k]), hi.max(p[k])));
        hi - lo
    };
    let axis = (0..3).max_by(|a, b| extent(*a).total_cmp(&extent(*b))).unwrap_or(2);
    let slabs = move |count: &str| {
        let n: Vec<&str> = (0..3).map(|k| if k == axis { count } else { "1" }).collect();
        format!("({})", n.join(" "))
    };
    (["x", "y", "z"][axis], slabs)
}

/// Placeholder values of the case templates.
fn case_vars(poly: &PolyMesh, ends: &EndNames, config: &OpenFoamConfig) -> Result<Vec<(&'static str, String)>> {
    let inflow = inlet_fields(poly, ends, config)?;
    let (application, ddt, div_u, end_time, delta_t, write_control, write_interval, adjust) = match config.solver {
        FoamSolver::SimpleFoam => (
            "simpleFoam",
            "steadyState",
            "bounded Gauss linearUpwind grad(U)",
            config.iterations.to_string(),
            "1".to_string(),
            "timeStep",
            config.iterations.to_string(),
            "no",
        ),
        FoamSolver::PimpleFoam => {
            let end = config.end_time.unwrap_or(2.0 * poly.volume() / inflow.flow_rate);
            let dt = 0.5 * min_centre_distance(poly) / inflow.max_speed;
            (
                "pimpleFoam",
                "Euler",
                "Gauss linearUpwind grad(U)",
                num(end),
                num(dt),
                "adjustableRunTime",
                num(end / 10.0),
                "yes",
            )
        }
    };
    let (axis, slabs) = slab_axis(poly);
    let mut vars = end_vars(ends)?;
    vars.extend(extension_wall_vars(poly));
    vars.extend([
        ("slab_axis", axis.to_string()),
        ("slabs_2", slabs("2")),
        ("slabs_np", slabs("$np")),
        ("version", env!("CARGO_PKG_VERSION").to_string()),
        ("application", application.into()),
        ("ddt_scheme", ddt.into()),
        ("div_u_scheme", div_u.into()),
        ("end_time", end_time),
        ("delta_t", delta_t),
        ("write_control", write_control.into()),
        ("write_interval", write_interval),
        ("adjust_time_step", adjust.into()),
        ("nu", num(config.nu)),
        ("inflow", inflow.summary),
        ("inlets_U", inflow.entries),
    ]);
    Ok(vars)
}

fn write_text(case: &Path, rel: &str, text: &str, executable: bool) -> Result<PathBuf> {
    super::write_text_file(case, rel, text, executable)?;
    Ok(PathBuf::from(rel))
}

fn prefixed(folder: &str, paths: Vec<PathBuf>) -> Vec<PathBuf> {
    paths.into_iter().map(|p| Path::new(folder).join(p)).collect()
}

/// Writes the lumen case into `dir/openfoam/`.
pub fn write_openfoam(mesh: &VesselMesh, options: &WriteOptions, dir: &Path) -> Result<Vec<PathBuf>> {
    write_openfoam_of(mesh, &lumen_polymesh(mesh)?, options, dir)
}

/// [`write_openfoam`] with the lumen polyMesh of `mesh` already built ([`lumen_polymesh`]): a run
/// that writes several of the formats derived from it builds it once.
pub fn write_openfoam_of(
    mesh: &VesselMesh,
    lumen: &PolyMesh,
    options: &WriteOptions,
    dir: &Path,
) -> Result<Vec<PathBuf>> {
    write_case(lumen, &EndNames::of(mesh)?, options, &dir.join("openfoam")).map(|p| prefixed("openfoam", p))
}

/// Writes a case for an already built lumen polyMesh with the end patches `ends` into `case`
/// (paths returned relative to it).
pub fn write_case(poly: &PolyMesh, ends: &EndNames, options: &WriteOptions, case: &Path) -> Result<Vec<PathBuf>> {
    options.openfoam.validate()?;
    let vars = case_vars(poly, ends, &options.openfoam)?;
    let mut out = write_polymesh(poly, options.openfoam.binary, case)?;
    for (rel, text) in TEMPLATES {
        let rendered = render(rel, text, &vars)?;
        out.push(write_text(case, rel, &rendered, *rel == "Allrun")?);
    }
    Ok(out)
}

/// Writes lumen + wall in one polyMesh into `dir/openfoam-fsi/`, with the system files that
/// OpenFOAM utilities need, `constant/polyMesh/fluidSolidZones` and an `Allrun` that splits the regions.
pub fn write_openfoam_fsi(mesh: &VesselMesh, options: &WriteOptions, dir: &Path) -> Result<Vec<PathBuf>> {
    // The lumen's polyMesh is gone before the whole one is built.
    let values = FsiSystemValues::of(mesh, &lumen_polymesh(mesh)?, options)?;
    let mut out = write_openfoam_fsi_mesh(mesh, options, dir)?;
    out.extend(write_openfoam_fsi_system(mesh, &values, dir)?);
    Ok(out)
}

/// The values of the `openfoam-fsi` system files and `Allrun`: those of the flow case, from the
/// lumen's polyMesh, which a run writing the flow case too builds once.
pub struct FsiSystemValues(Vec<(&'static str, String)>);

impl FsiSystemValues {
    /// The values for `mesh`, whose lumen polyMesh is `lumen` ([`lumen_polymesh`]).
    pub fn of(mesh: &VesselMesh, lumen: &PolyMesh, options: &WriteOptions) -> Result<Self> {
        case_vars(lumen, &EndNames::of(mesh)?, &options.openfoam).map(FsiSystemValues)
    }
}

/// The polyMesh of [`write_openfoam_fsi`] (`openfoam-fsi/constant/polyMesh/`), built, written
/// and dropped: a run can write it before it builds the lumen's, never holding both.
pub fn write_openfoam_fsi_mesh(mesh: &VesselMesh, options: &WriteOptions, dir: &Path) -> Result<Vec<PathBuf>> {
    let poly = fsi_polymesh(mesh)?;
    write_polymesh(&poly, options.openfoam.binary, &dir.join("openfoam-fsi")).map(|p| prefixed("openfoam-fsi", p))
}

/// The rest of [`write_openfoam_fsi`]: the system files, `Allrun` and
/// `constant/polyMesh/fluidSolidZones`.
pub fn write_openfoam_fsi_system(mesh: &VesselMesh, values: &FsiSystemValues, dir: &Path) -> Result<Vec<PathBuf>> {
    let (case, vars) = (dir.join("openfoam-fsi"), &values.0);
    let mut out = Vec::new();
    for (rel, text) in TEMPLATES.iter().filter(|(rel, _)| rel.starts_with("system/")) {
        out.push(write_text(&case, rel, &render(rel, text, vars)?, false)?);
    }
    out.push(write_text(&case, "Allrun", &render("openfoam-fsi/Allrun", FSI_ALLRUN, vars)?, true)?);
    let cells = |r: Range<usize>| r.start as u32..r.end as u32;
    let fluid: Vec<u32> = cells(mesh.lumen_range()).chain(cells(mesh.extension_range())).collect();
    let zones = vec![("fluid".to_string(), fluid), ("solid".to_string(), cells(mesh.wall_range()).collect())];
    // splitMeshRegions -cellZonesFileOnly reads the file from constant/polyMesh.
    let path = case.join("constant/polyMesh/fluidSolidZones");
    write_atomic(&path, |w| write_cell_zones(w, "constant/polyMesh", "fluidSolidZones", &zones))?;
    out.push(PathBuf::from("constant/polyMesh/fluidSolidZones"));
    Ok(prefixed("openfoam-fsi", out))
}

// ---------------------------------------------------------------------------------------------
// Reading back (tests, tools): the files this module writes, ASCII or binary.

fn read_err(path: &Path, what: impl Into<String>) -> Error {
    Error::input(path, what.into())
}

/// Splits a file into (header format is binary, body after the FoamFile dictionary).
fn split_header(path: &Path) -> Result<(bool, Vec<u8>)> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, "cannot read", e))?;
    let start = find(&bytes, b"FoamFile", 0).ok_or_else(|| read_err(path, "no FoamFile header"))?;
    let close = find(&bytes, b"}", start).ok_or_else(|| read_err(path, "unterminated FoamFile header"))?;
    let head = String::from_utf8_lossy(&bytes[start..close]);
    let binary = head.lines().any(|l| {
        let mut t = l.split_whitespace();
        t.next() == Some("format") && t.next() == Some("binary;")
    });
    Ok((binary, bytes[close + 1..].to_vec()))
}

fn find(hay: &[u8], needle: &[u8], from: usize) -> Option<usize> {
    hay[from..].windows(needle.len()).position(|w| w == needle).map(|i| i + from)
}

/// Skips whitespace and `//` comments.
fn skip_ws(b: &[u8], mut i: usize) -> usize {
    loop {
        while i < b.len() && b[i].is_ascii_whitespace() {
            i += 1;
        }
        if b[i..].starts_with(b"//") {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else {
            return i;
        }
    }
}

/// Reads `N (` at `i`; returns N and the position after `(`.
fn list_start(path: &Path, b: &[u8], i: usize) -> Result<(usize, usize)> {
    let i = skip_ws(b, i);
    let end = i + b[i..].iter().take_while(|c| c.is_ascii_digit()).count();
    let n: usize = std::str::from_utf8(&b[i..end])
        .ok()
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| read_err(path, "expected a list size"))?;
    let j = skip_ws(b, end);
    if b.get(j) != Some(&b'(') {
        return Err(read_err(path, "expected '(' after the list size"));
    }
    Ok((n, j + 1))
}

fn binary_labels(path: &Path, b: &[u8], i: usize) -> Result<(Vec<u32>, usize)> {
    let (n, s) = list_start(path, b, i)?;
    let e = s + 4 * n;
    if b.len() < e + 1 || b[e] != b')' {
        return Err(read_err(path, "binary label list of the wrong length"));
    }
    Ok((b[s..e].chunks_exact(4).map(|c| i32::from_le_bytes([c[0], c[1], c[2], c[3]]) as u32).collect(), e + 1))
}

/// ASCII tokens of a list body up to its closing ')', parentheses dropped.
fn ascii_items(path: &Path, b: &[u8], i: usize) -> Result<(usize, Vec<String>)> {
    let (n, s) = list_start(path, b, i)?;
    let mut depth = 1;
    let mut j = s;
    while depth > 0 {
        match b.get(j) {
            Some(b'(') => depth += 1,
            Some(b')') => depth -= 1,
            None => return Err(read_err(path, "unterminated list")),
            _ => {}
        }
        j += 1;
    }
    let text = String::from_utf8_lossy(&b[s..j - 1]).replace(['(', ')'], " ");
    Ok((n, text.split_whitespace().map(str::to_string).collect()))
}

fn parse_all<T: std::str::FromStr>(path: &Path, items: &[String]) -> Result<Vec<T>> {
    items.iter().map(|s| s.parse().map_err(|_| read_err(path, format!("cannot read '{s}'")))).collect()
}

/// Reads `case/constant/polyMesh` (points, faces, owner, neighbour, boundary; zones are not
/// read). Only the layout this module writes is supported: quadrilateral faces.
pub fn read_polymesh(case: &Path) -> Result<PolyMesh> {
    let dir = case.join("constant/polyMesh");
    let p = dir.join("points");
    let (bin, b) = split_header(&p)?;
    let points: Vec<Point3<f64>> = if bin {
        let (n, s) = list_start(&p, &b, 0)?;
        b[s..s + 24 * n]
            .chunks_exact(24)
            .map(|c| {
                let v = |k: usize| f64::from_le_bytes(c[8 * k..8 * k + 8].try_into().unwrap());
                Point3::new(v(0), v(1), v(2))
            })
            .collect()
    } else {
        let (n, items) = ascii_items(&p, &b, 0)?;
        let v: Vec<f64> = parse_all(&p, &items)?;
        if v.len() != 3 * n {
            return Err(read_err(&p, "wrong number of coordinates"));
        }
        v.chunks_exact(3).map(|c| Point3::new(c[0], c[1], c[2])).collect()
    };
    let p = dir.join("faces");
    let (bin, b) = split_header(&p)?;
    let faces: Vec<[u32; 4]> = if bin {
        let (offsets, next) = binary_labels(&p, &b, 0)?;
        let (flat, _) = binary_labels(&p, &b, next)?;
        if offsets.windows(2).any(|w| w[1] - w[0] != 4) {
            return Err(read_err(&p, "only quadrilateral faces are supported"));
        }
        flat.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect()
    } else {
        let (n, items) = ascii_items(&p, &b, 0)?;
        if items.len() != 5 * n {
            return Err(read_err(&p, "only quadrilateral faces are supported"));
        }
        items
            .chunks_exact(5)
            .map(|c| -> Result<[u32; 4]> {
                if !c[0].starts_with('4') {
                    return Err(read_err(&p, "only quadrilateral faces are supported"));
                }
                let v: Vec<u32> = parse_all(&p, &c[1..])?;
                Ok([v[0], v[1], v[2], v[3]])
            })
            .collect::<Result<_>>()?
    };
    let labels = |name: &str| -> Result<Vec<u32>> {
        let p = dir.join(name);
        let (bin, b) = split_header(&p)?;
        if bin && list_start(&p, &b, 0)?.0 > 0 {
            Ok(binary_labels(&p, &b, 0)?.0)
        } else {
            parse_all(&p, &ascii_items(&p, &b, 0)?.1)
        }
    };
    let owner = labels("owner")?;
    let neighbour = labels("neighbour")?;
    let p = dir.join("boundary");
    let text: String = String::from_utf8_lossy(&split_header(&p)?.1)
        .lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n");
    let tokens: Vec<&str> = text.split(|c: char| c.is_whitespace() || c == ';').filter(|t| !t.is_empty()).collect();
    let mut patches = Vec::new();
    let mut k = 2; // after "N" "("
    while k < tokens.len() && tokens[k] != ")" {
        let name = tokens[k].to_string();
        let close = k + tokens[k..].iter().position(|t| *t == "}").ok_or_else(|| read_err(&p, "unterminated patch"))?;
        let get = |key: &str| tokens[k..close].iter().position(|t| *t == key).map(|i| tokens[k + i + 1]);
        let num = |key: &str| {
            get(key)
                .and_then(|v| v.parse::<usize>().ok())
                .ok_or_else(|| read_err(&p, format!("patch {name}: no {key}")))
        };
        let kind = if get("type") == Some("wall") { PatchKind::Wall } else { PatchKind::Patch };
        patches.push(Patch { kind, size: num("nFaces")?, start: num("startFace")?, name });
        k = close + 1;
    }
    let n_cells = owner.iter().chain(&neighbour).map(|&c| c as usize + 1).max().unwrap_or(0);
    Ok(PolyMesh { points, faces, owner, neighbour, patches, cell_zones: vec![], face_zones: vec![], n_cells })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::config::MeshConfig;
    use crate::testing::straight_tube_mesh;

    fn tube() -> VesselMesh {
        straight_tube_mesh(&MeshConfig::default()).unwrap().mesh
    }

    #[test]
    fn render_is_strict() {
        let vars = [("a", "1".to_string())];
        assert_eq!(render("t", "x {{a}} y", &vars).unwrap(), "x 1 y");
        let e = render("t", "x {{b}} y", &vars).unwrap_err().to_string();
        assert!(e.contains("{{b}}") && e.contains("t"), "{e}");
        assert!(render("t", "x {{a", &vars).is_err());
        let poly = lumen_polymesh(&tube()).unwrap();
        let ends = EndNames::of(&tube()).unwrap();
        for solver in [FoamSolver::SimpleFoam, FoamSolver::PimpleFoam] {
            let vars = case_vars(&poly, &ends, &OpenFoamConfig { solver, ..Default::default() }).unwrap();
            for (rel, text) in TEMPLATES {
                assert!(!render(rel, text, &vars).unwrap().contains("{{"), "{rel}");
            }
            render("fsi", FSI_ALLRUN, &vars).unwrap();
        }
    }

    #[test]
    fn lumen_polymesh_follows_the_rules() {
        let m = tube();
        let poly = lumen_polymesh(&m).unwrap();
        assert_eq!(poly.verify(), Vec::<String>::new());
        assert_eq!(poly.n_cells, m.count(Region::Lumen));
        let names: Vec<&str> = poly.patches.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["inlet", "outlet", "wall"]);
        assert_eq!(poly.patches[2].kind, PatchKind::Wall);
        // metres: the tube is 30 mm long
        let zmax = poly.points.iter().map(|p| p.z).fold(f64::MIN, f64::max);
        assert!(zmax > 0.025 && zmax < 0.031, "{zmax}");
    }

    #[test]
    fn fsi_polymesh_has_zones_and_an_internal_interface() {
        let m = tube();
        let poly = fsi_polymesh(&m).unwrap();
        assert_eq!(poly.verify(), Vec::<String>::new());
        assert_eq!(poly.n_cells, m.hexes.len());
        let zones: Vec<&str> = poly.cell_zones.iter().map(|z| z.0.as_str()).collect();
        assert_eq!(zones, ["lumen", "intima", "media", "adventitia"]);
        let z = &poly.face_zones[0];
        assert_eq!(z.faces.len(), m.face_sets[sets::LUMEN_WALL_FACES].len());
        assert!(z.faces.iter().all(|&f| (f as usize) < poly.n_internal()));
        assert!(z.flip.iter().all(|f| !f));
    }

    #[test]
    fn parabolic_inflow_has_the_flow_rate_and_vanishes_at_the_wall() {
        let m = tube();
        let poly = lumen_polymesh(&m).unwrap();
        let inlet = poly.patch("inlet").unwrap();
        let inflow = inlet_velocities(&poly, inlet, InletProfile::Parabolic, 2e-6);
        let flux: f64 = inlet.range().zip(&inflow.velocities).map(|(f, u)| u.dot(&poly.face_area(f))).sum();
        assert!((flux + 2e-6).abs() < 1e-18, "{flux}");
        let speeds: Vec<f64> = inflow.velocities.iter().map(|v| v.norm()).collect();
        let mean = 2e-6 / inflow.area;
        let max = speeds.iter().copied().fold(0.0, f64::max);
        assert!(max > 1.6 * mean && max < 2.2 * mean, "{max} vs mean {mean}");
        assert!(inflow.velocities.iter().all(|v| v.z > 0.0));
    }

    #[test]
    fn ascii_and_binary_read_back_equal_and_output_is_deterministic() {
        let m = tube();
        let base = std::env::temp_dir().join(format!("vesselhex-foam-unit-{}", std::process::id()));
        let mut read = Vec::new();
        for (k, binary) in [false, true, false].into_iter().enumerate() {
            let dir = base.join(k.to_string());
            let options = WriteOptions {
                openfoam: crate::data::config::OpenFoamConfig { binary, ..Default::default() },
                ..Default::default()
            };
            write_openfoam(&m, &options, &dir).unwrap();
            read.push(read_polymesh(&dir.join("openfoam")).unwrap());
        }
        let poly = lumen_polymesh(&m).unwrap();
        let strip = |mut p: PolyMesh| {
            p.cell_zones.clear();
            p.face_zones.clear();
            p
        };
        let first_difference = |a: &PolyMesh, b: &PolyMesh| -> Option<String> {
            let i = (0..a.points.len()).find(|&i| a.points.get(i) != b.points.get(i));
            if let Some(i) = i {
                return Some(format!("point {i}: {:?} vs {:?}", a.points[i], b.points.get(i)));
            }
            let i = (0..a.faces.len()).find(|&i| a.faces.get(i) != b.faces.get(i));
            if let Some(i) = i {
                return Some(format!("face {i}: {:?} vs {:?}", a.faces[i], b.faces.get(i)));
            }
            for (name, x, y) in [("owner", &a.owner, &b.owner), ("neighbour", &a.neighbour, &b.neighbour)] {
                if x != y {
                    return Some(format!("{name} differs ({} vs {} entries)", x.len(), y.len()));
                }
            }
            (a != b).then(|| format!("{:?} {} vs {:?} {}", a.patches, a.n_cells, b.patches, b.n_cells))
        };
        assert_eq!(first_difference(&read[0], &strip(poly.clone())), None);
        assert_eq!(first_difference(&read[1], &read[0]), None);
        for f in ["points", "faces", "owner", "neighbour", "boundary", "cellZones"] {
            let a = std::fs::read(base.join("0/openfoam/constant/polyMesh").join(f)).unwrap();
            let b = std::fs::read(base.join("2/openfoam/constant/polyMesh").join(f)).unwrap();
            assert!(a == b, "{f} differs between two runs");
        }
        std::fs::remove_dir_all(&base).ok();
    }

    #[test]
    fn case_file_section_reaches_the_config() {
        let dir = std::env::temp_dir().join(format!("vesselhex-foam-config-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("case.toml");
        let text = "[openfoam]\nsolver = \"pimpleFoam\"\nprofile = \"plug\"\nflow_rate_ml_s = 3.0\nbinary = true\n";
        std::fs::write(&p, text).unwrap();
        let c = MeshConfig::from_case_file(&p, None).unwrap();
        assert_eq!(c.openfoam.solver, FoamSolver::PimpleFoam);
        assert_eq!(c.openfoam.profile, InletProfile::Plug);
        assert_eq!(c.openfoam.flow_rate_ml_s, Some(3.0));
        assert!(c.openfoam.binary);
        assert_eq!(c.openfoam.nu, 3.5e-6);
        std::fs::write(&p, "[openfoam]\nmean_velocity = -1.0\n").unwrap();
        let e = MeshConfig::from_case_file(&p, None).unwrap_err().to_string();
        assert!(e.contains("openfoam.mean_velocity"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
