//! FSI coupling package (`fsi/`): the exact map between the fluid (OpenFOAM `openfoam/`) and the
//! solid (CalculiX `calculix/`, same labels in Abaqus and FEBio) interface, and ready preCICE
//! configuration files for a partitioned OpenFOAM + CalculiX run.
//!
//! # The map
//! Lumen and wall share their interface nodes, so every point of the OpenFOAM `wall` patch is
//! one solid node and every `wall` face is one face of one wall element:
//! * `interface_nodes.csv`, `fluid_point,solid_node,x,y,z`: one row per point of the `wall`
//!   patch, ascending by fluid point label (0-based position in `openfoam/constant/polyMesh/points`,
//!   which is the node's position in the sorted list of lumen nodes); solid node = node index + 1;
//!   coordinates in the FE length unit (`output_units`), shortest round-trip text.
//! * `interface_faces.csv`, `patch_face,face,solid_element,solid_face,area`: per `wall` face (its
//!   index in the patch and in `faces`) the wall element (1-based) and its face label S1..S6 with
//!   the same four nodes, and the face area (half the cross product of the diagonals) in FE
//!   unit^2.
//! * `force_lumping.csv`, `patch_face,solid_node,weight`: each face's four solid nodes with weight
//!   1/4. For a bilinear quad a uniform traction t on the face is statically equivalent to t A / 4
//!   at each corner (exact for a parallelogram, the consistent nodal load of a constant traction);
//!   summing `weight x face force` over the rows of a node gives its nodal force, and the total
//!   force is preserved exactly.
//!
//! # preCICE files
//! From `templates/fsi/` (embedded), placeholders `{{name}}` substituted strictly:
//! * `precice-config.xml` (v3): participants `Fluid` and `Solid`; meshes `Fluid-Mesh-Faces`
//!   (face centres, writes `Force`), `Fluid-Mesh-Nodes` (face nodes, reads `Displacement`) and
//!   `Solid-Mesh` (the interface nodes); nearest-neighbor mappings (write conservative, read
//!   consistent: the identity on the nodes of this conformal interface); serial-implicit coupling
//!   with IQN-ILS on the displacement.
//! * `openfoam/`: an overlay of the `openfoam/` case (copied over it by `fsi/Allrun` into
//!   `fsi/fluid/`, so the plain flow case stays runnable without the adapter): `system/preciceDict`,
//!   `system/controlDict` (pimpleFoam, fixed time step = the coupling window, adapter function
//!   object), `system/fvSchemes` (Euler), `system/fvSolution` (with the mesh-motion solver),
//!   `constant/dynamicMeshDict` (displacementLaplacian), `0/pointDisplacement` (wall fixedValue,
//!   written by the adapter; ends `slip`), `0/U` (wall `movingWallVelocity`).
//! * `calculix/fsi.inp`: the wall model of `calculix/model.inp` **in SI units** (metres, like the
//!   fluid, since preCICE does not convert), the node set `NLUMEN_WALL` (the interface nodes, the
//!   adapter's `N<patch>`), a `*DYNAMIC` step with zero `*CLOAD` on it; `calculix/config.yml` for
//!   the CalculiX adapter (patch `lumen_wall`). The inflation deck is not changed. The end rings
//!   are held by `*EQUATION`s in global axes ([`EndHold::Equations`]: each ring node moves only
//!   along its radial direction in its end plane, oblique ends included), not by the inflation
//!   deck's cylindrical `*TRANSFORM`: the end rings hold interface nodes, and ccx would read the
//!   adapter's global-axis forces on a transformed node in its local axes.
//!
//! Only bilinear CalculiX elements (C3D8I, C3D8, C3D8R) are accepted: the map pairs fluid points
//! with corner nodes and lumps each face's force on its four corners, so a C3D20 wall would leave
//! its interface mid-edge nodes without force or displacement; `fe.calculix_element = C3D20*` is
//! refused with that reason.
//! * `Allrun` (`./Allrun N` runs the fluid on N MPI processes), `README.md`.
//!
//! Time: one fluid time step per coupling window, dt = min(1e-4 s, Courant 0.5 of the inflow);
//! end time `openfoam.end_time` or 100 windows.

use super::inp::{fmt_const, Dialect, EndHold, ModelData};
use super::openfoam::{
    end_vars, extension_wall_vars, inlet_fields, lumen_polymesh, render, slab_axis, EndNames, PolyMesh,
};
use super::text::{text_of, write_items, Text};
use super::{write_atomic, WriteOptions};
use crate::data::error::{Error, Result};
use crate::data::units::LengthUnit;
use crate::geometry::mesh::{face_nodes, quad_area_vector, sets, VesselMesh};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// preCICE participant of the fluid solver.
pub const FLUID: &str = "Fluid";
/// preCICE participant of the solid solver.
pub const SOLID: &str = "Solid";
/// Fluid mesh of the face centres (writes the force).
pub const FLUID_FACES_MESH: &str = "Fluid-Mesh-Faces";
/// Fluid mesh of the face nodes (reads the displacement).
pub const FLUID_NODES_MESH: &str = "Fluid-Mesh-Nodes";
/// Solid mesh of the interface nodes.
pub const SOLID_MESH: &str = "Solid-Mesh";
/// Data names (the adapters recognise them by these prefixes).
pub const FORCE: &str = "Force";
pub const DISPLACEMENT: &str = "Displacement";
/// The OpenFOAM interface patch.
pub const FLUID_PATCH: &str = "wall";
/// The CalculiX adapter's patch: node set `N` + patch in the deck.
pub const SOLID_PATCH: &str = "lumen_wall";
/// Blood density, kg/m3, for the adapter's FSI module (kinematic pressure -> force).
pub const BLOOD_DENSITY: f64 = 1060.0;

/// One interface point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodePair {
    /// 0-based OpenFOAM point label.
    pub fluid_point: u32,
    /// 0-based mesh node index (solid label = index + 1).
    pub node: u32,
}

impl NodePair {
    pub fn solid_label(&self) -> u64 {
        self.node as u64 + 1
    }
}

/// One interface face.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FacePair {
    /// Index in the `wall` patch.
    pub patch_face: usize,
    /// Index in `faces`.
    pub face: usize,
    /// 0-based wall element index (label = index + 1).
    pub element: u32,
    /// Canonical face index (label S{face+1}).
    pub solid_face: u8,
    /// The four mesh nodes of the face (the solid face's corners).
    pub nodes: [u32; 4],
    /// Area in mm^2 (mesh unit).
    pub area_mm2: f64,
}

/// The fluid-solid interface map.
#[derive(Debug, Clone)]
pub struct InterfaceMap {
    pub nodes: Vec<NodePair>,
    pub faces: Vec<FacePair>,
}

fn sorted4(mut q: [u32; 4]) -> [u32; 4] {
    q.sort_unstable();
    q
}

/// Builds the map for the lumen polyMesh `poly` of `mesh` ([`lumen_polymesh`]). Fails if the
/// interface is not conformal (a wall face without its solid twin, or nodes that differ from the
/// mesh's interface node set).
pub fn interface_map(mesh: &VesselMesh, poly: &PolyMesh) -> Result<InterfaceMap> {
    let fail = |m: String| Error::Geometry(format!("FSI map: {m}"));
    let lumen_nodes = mesh.fluid_nodes();
    let patch = poly.patch(FLUID_PATCH).ok_or_else(|| fail("the fluid mesh has no 'wall' patch".into()))?;
    let lumen_faces = mesh
        .face_sets
        .get(sets::LUMEN_WALL_FACES)
        .ok_or_else(|| fail(format!("the mesh has no face set {}", sets::LUMEN_WALL_FACES)))?;
    let wall_faces = mesh
        .face_sets
        .get(sets::WALL_LUMEN_FACES)
        .ok_or_else(|| fail(format!("the mesh has no face set {}", sets::WALL_LUMEN_FACES)))?;
    if lumen_faces.len() != patch.size || wall_faces.len() != patch.size {
        return Err(fail(format!(
            "{} wall patch faces, {} lumen interface faces, {} wall interface faces",
            patch.size,
            lumen_faces.len(),
            wall_faces.len()
        )));
    }
    let mut twin: HashMap<[u32; 4], (u32, u8)> = HashMap::with_capacity(wall_faces.len());
    for f in wall_faces {
        let key = sorted4(face_nodes(&mesh.hexes[f.element as usize], f.face as usize));
        if twin.insert(key, (f.element, f.face)).is_some() {
            return Err(fail(format!("two wall faces on the nodes {key:?}")));
        }
    }
    let mut faces = Vec::with_capacity(patch.size);
    let mut used = vec![false; lumen_nodes.len()];
    for (k, face) in patch.range().enumerate() {
        let points = poly.faces[face];
        let nodes = points.map(|p| lumen_nodes[p as usize]);
        let lf = lumen_faces[k];
        if sorted4(nodes) != sorted4(face_nodes(&mesh.hexes[lf.element as usize], lf.face as usize)) {
            return Err(fail(format!("wall patch face {k} is not the lumen face {lf:?}")));
        }
        let (element, solid_face) =
            *twin.get(&sorted4(nodes)).ok_or_else(|| fail(format!("wall patch face {k} has no solid twin")))?;
        let corners = face_nodes(&mesh.hexes[element as usize], solid_face as usize);
        let area_mm2 = quad_area_vector(corners.map(|n| mesh.nodes[n as usize])).norm();
        for p in points {
            used[p as usize] = true;
        }
        faces.push(FacePair { patch_face: k, face, element, solid_face, nodes: corners, area_mm2 });
    }
    let nodes: Vec<NodePair> = used
        .iter()
        .enumerate()
        .filter(|(_, u)| **u)
        .map(|(p, _)| NodePair { fluid_point: p as u32, node: lumen_nodes[p] })
        .collect();
    if let Some(set) = mesh.node_sets.get(sets::INTERFACE_NODES) {
        let mut ours: Vec<u32> = nodes.iter().map(|n| n.node).collect();
        ours.sort_unstable();
        if &ours != set {
            return Err(fail(format!(
                "the wall patch has {} points but the node set {} has {} nodes",
                ours.len(),
                sets::INTERFACE_NODES,
                set.len()
            )));
        }
    }
    Ok(InterfaceMap { nodes, faces })
}

/// Shortest round-trip text of a float (no "-0").
fn num(x: f64) -> String {
    text_of(|t| {
        push_num(t, x);
    })
}

/// [`num`] appended to a text.
fn push_num(t: &mut Text, x: f64) -> &mut Text {
    t.debug(if x == 0.0 { 0.0 } else { x })
}

/// Writes `fsi/<rel>`: a header line, then the lines of items `0..n`.
fn write_csv(fsi: &Path, rel: &str, header: &str, n: usize, line: impl Fn(&mut Text, usize) + Sync) -> Result<PathBuf> {
    write_atomic(&fsi.join(rel), |w| {
        w.write_all(header.as_bytes())?;
        write_items(w, n, line)
    })?;
    Ok(Path::new("fsi").join(rel))
}

fn write_file(dir: &Path, rel: &str, text: &str, executable: bool) -> Result<PathBuf> {
    super::write_text_file(dir, rel, text, executable)?;
    Ok(Path::new("fsi").join(rel))
}

const TEMPLATES: &[(&str, &str)] = &[
    ("precice-config.xml", include_str!("../../templates/fsi/precice-config.xml")),
    ("openfoam/system/preciceDict", include_str!("../../templates/fsi/openfoam/system/preciceDict")),
    ("openfoam/system/controlDict", include_str!("../../templates/fsi/openfoam/system/controlDict")),
    ("openfoam/system/fvSchemes", include_str!("../../templates/openfoam/system/fvSchemes")),
    ("openfoam/system/fvSolution", include_str!("../../templates/fsi/openfoam/system/fvSolution")),
    ("openfoam/constant/dynamicMeshDict", include_str!("../../templates/fsi/openfoam/constant/dynamicMeshDict")),
    ("openfoam/0/pointDisplacement", include_str!("../../templates/fsi/openfoam/0/pointDisplacement")),
    ("openfoam/0/U", include_str!("../../templates/fsi/openfoam/0/U")),
    ("calculix/config.yml", include_str!("../../templates/fsi/calculix/config.yml")),
    ("Allrun", include_str!("../../templates/fsi/Allrun")),
    ("README.md", include_str!("../../templates/fsi/README.md")),
];
const STEP_TEMPLATE: &str = include_str!("../../templates/fsi/calculix/step_fsi.inp");
/// The `pointDisplacement` entry of one end patch (inlet or outlet), `{{end}}` = its name.
const END_PIECE: (&str, &str) = (
    "templates/fsi/openfoam/0/pointDisplacement.end",
    include_str!("../../templates/fsi/openfoam/0/pointDisplacement.end"),
);

/// Coupling time window and end time, s.
fn timing(poly: &PolyMesh, options: &WriteOptions, u_max: f64) -> (f64, f64) {
    let c = poly.cell_centres();
    let h = (0..poly.n_internal())
        .map(|f| (c[poly.neighbour[f] as usize] - c[poly.owner[f] as usize]).norm())
        .fold(f64::INFINITY, f64::min);
    let courant = if u_max > 0.0 && h.is_finite() { 0.5 * h / u_max } else { 1e-4 };
    // Round down to one significant digit so that end / dt is a whole number of windows.
    let dt = courant.min(1e-4);
    let p = 10f64.powf(dt.log10().floor());
    let dt = (dt / p).floor() * p;
    let end = options.openfoam.end_time.map(|t| (t / dt).round().max(1.0) * dt).unwrap_or(100.0 * dt);
    (dt, end)
}

/// Writes `fsi/` under `dir` (see the module documentation).
pub fn write_fsi(mesh: &VesselMesh, options: &WriteOptions, dir: &Path) -> Result<Vec<PathBuf>> {
    options.openfoam.validate()?;
    check_element(options)?;
    write_fsi_of(mesh, &lumen_polymesh(mesh)?, options, dir)
}

/// The map pairs each fluid point with one corner node, and the lumping gives each face's force
/// to its four corners (1/4 each, right for bilinear faces): a C3D20 face has four more nodes on
/// the interface, which would get neither force nor displacement.
fn check_element(options: &WriteOptions) -> Result<()> {
    let element = options.fe.calculix_element;
    if element.is_quadratic() {
        return Err(Error::Config(format!(
            "fe.calculix_element = {}: the FSI package couples the fluid points to the corner nodes of bilinear faces \
             only; quadratic elements have mid-edge nodes on the interface that the map cannot serve. Use C3D8I (the \
             default), C3D8 or C3D8R with the fsi format",
            element.name()
        )));
    }
    Ok(())
}

/// [`write_fsi`] with the lumen polyMesh of `mesh` already built ([`lumen_polymesh`]): a run
/// that writes the flow case too builds it once.
pub fn write_fsi_of(mesh: &VesselMesh, poly: &PolyMesh, options: &WriteOptions, dir: &Path) -> Result<Vec<PathBuf>> {
    options.openfoam.validate()?;
    check_element(options)?;
    let map = interface_map(mesh, poly)?;
    let fsi = dir.join("fsi");
    std::fs::create_dir_all(&fsi).map_err(|e| Error::io(&fsi, "cannot create the folder", e))?;
    let unit = options.length_unit;
    let scale = unit.from_mm();
    let mut out = Vec::new();

    // The map.
    out.push(write_csv(&fsi, "interface_nodes.csv", "fluid_point,solid_node,x,y,z\n", map.nodes.len(), |t, i| {
        let n = map.nodes[i];
        let p = mesh.nodes[n.node as usize].coords * scale;
        t.uint(n.fluid_point as u64).byte(b',').uint(n.solid_label()).byte(b',');
        push_num(t, p.x).byte(b',');
        push_num(t, p.y).byte(b',');
        push_num(t, p.z).byte(b'\n');
    })?);
    let faces_header = "patch_face,face,solid_element,solid_face,area\n";
    out.push(write_csv(&fsi, "interface_faces.csv", faces_header, map.faces.len(), |t, i| {
        let f = &map.faces[i];
        t.uint(f.patch_face as u64).byte(b',').uint(f.face as u64).byte(b',');
        t.uint(f.element as u64 + 1).str(",S").uint(f.solid_face as u64 + 1).byte(b',');
        push_num(t, f.area_mm2 * scale * scale).byte(b'\n');
    })?);
    let lumping_header = "patch_face,solid_node,weight\n";
    out.push(write_csv(&fsi, "force_lumping.csv", lumping_header, map.faces.len(), |t, i| {
        let f = &map.faces[i];
        for n in f.nodes {
            t.uint(f.patch_face as u64).byte(b',').uint(n as u64 + 1).str(",0.25\n");
        }
    })?);

    // Case values.
    let ends = EndNames::of(mesh)?;
    let inflow = inlet_fields(poly, &ends, &options.openfoam)?;
    let (dt, end) = timing(poly, options, inflow.max_speed);
    let mut end_patches = String::new();
    for end in ends.all() {
        end_patches.push_str(&render(END_PIECE.0, END_PIECE.1, &[("end", end.to_string())])?);
    }
    let windows = (end / dt).round().max(1.0) as u64;
    let (_, slabs) = slab_axis(poly);
    let mut vars: Vec<(&str, String)> = end_vars(&ends)?;
    vars.extend(extension_wall_vars(poly));
    vars.extend([
        ("slabs_np", slabs("$np")),
        ("version", env!("CARGO_PKG_VERSION").to_string()),
        ("fluid", FLUID.into()),
        ("solid", SOLID.into()),
        ("fluid_faces_mesh", FLUID_FACES_MESH.into()),
        ("fluid_nodes_mesh", FLUID_NODES_MESH.into()),
        ("solid_mesh", SOLID_MESH.into()),
        ("force", FORCE.into()),
        ("displacement", DISPLACEMENT.into()),
        ("patch", FLUID_PATCH.into()),
        ("solid_patch", SOLID_PATCH.into()),
        ("solid_patch_upper", SOLID_PATCH.to_ascii_uppercase()),
        ("rho", num(BLOOD_DENSITY)),
        ("time_window", format!("{dt:e}")),
        ("end_time", format!("{end:e}")),
        ("write_every", (windows / 10).max(1).to_string()),
        ("end_patches", end_patches),
        ("inlets_U", inflow.entries),
        ("inflow", inflow.summary),
        // fvSchemes of the flow case, transient.
        ("ddt_scheme", "Euler".into()),
        ("div_u_scheme", "Gauss linearUpwind grad(U)".into()),
        ("unit", unit.name().into()),
        ("n_nodes", map.nodes.len().to_string()),
        ("n_faces", map.faces.len().to_string()),
    ]);
    for (rel, template) in TEMPLATES {
        let text = render(&format!("templates/fsi/{rel}"), template, &vars)?;
        out.push(write_file(&fsi, rel, &text, *rel == "Allrun")?);
    }

    // The FSI deck: the wall model in SI units + the interface set + the dynamic step.
    let mut si = options.clone();
    si.length_unit = LengthUnit::M;
    let model = ModelData::new(mesh, &si, Dialect::Calculix, EndHold::Equations)?;
    let nset = format!("N{}", SOLID_PATCH.to_ascii_uppercase());
    let mut labels: Vec<u64> = map.nodes.iter().map(|n| n.solid_label()).collect();
    labels.sort_unstable();
    let step = render(
        "templates/fsi/calculix/step_fsi.inp",
        STEP_TEMPLATE,
        &[
            ("SOLID", SOLID.into()),
            ("TIME_WINDOW", fmt_const(dt)),
            ("END_TIME", fmt_const(end)),
            ("NSET", nset.clone()),
            ("UNITS", crate::data::units::MechanicalUnits::of(LengthUnit::M).describe()),
        ],
    )?;
    let rel = "calculix/fsi.inp";
    std::fs::create_dir_all(fsi.join("calculix"))
        .map_err(|e| Error::io(fsi.join("calculix"), "cannot create the folder", e))?;
    write_atomic(&fsi.join(rel), |w| {
        model.write(w)?;
        writeln!(
            w,
            "** preCICE interface: the lumen-wall nodes ({} nodes, = LUMEN_WALL_INTERFACE), set N + adapter patch '{}'.\n*NSET, NSET={nset}",
            map.nodes.len(),
            SOLID_PATCH
        )?;
        write_items(w, labels.len().div_ceil(16), |t, i| {
            t.uints(labels[16 * i..(16 * i + 16).min(labels.len())].iter().copied(), ", ").byte(b'\n');
        })?;
        w.write_all(step.as_bytes())
    })?;
    out.push(Path::new("fsi").join(rel));
    Ok(out)
}
