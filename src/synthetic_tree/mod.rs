//! Random vessel trees as segmentations give them (issue 46's population): `vesselhex fixtures
//! --random-tree SEED` writes one, with its truth.
//!
//! A seed maps to a tree. The tree is drawn as centerlines with radii ([`layout`]), its lumen is
//! the smooth union of tapered, tortuous tubes and saccular balls ([`lumen`]), triangulated by
//! the machinery of [`crate::implicit_surface`] on a grid chosen from the tree's smallest
//! radius: surface nets, Newton projection onto the implicit surface, light tangential
//! relaxation, ends cut open or capped flat, and the checks (manifold, one piece, genus 0, one
//! boundary loop per open end on its circle, flat caps in their planes, outward triangles, no
//! angle below 5°). A draw whose surface fails a check is drawn again from the seed's next
//! stream (the manifest says which attempts failed and why); a tree is never written broken.
//!
//! # Distributions (per seed; the manifest records every draw and every measured figure)
//!
//! * Ends: 2 with probability 0.05 (a single vessel), else log-uniform over 3..40. Places are
//!   added until the tree has them, the area budget is spent, or 30 drawn places in a row find
//!   no room (the manifest's `draws` gives the target and the ends laid).
//! * Scale: largest / smallest radius log-uniform in [1.5, 7]; smallest radius log-uniform in
//!   [0.3 mm, 15 mm / that ratio], so every radius lies in 0.3..15 mm. The grid cell is the
//!   smallest radius / 3.5 (a stenosis throat is never thinner than the smallest radius); the
//!   surface stays within about 80,000 cells² (about 240,000 triangles): the root takes at most
//!   40 % of it and each daughter at most its share of what is left per end still to lay.
//! * Root: from the origin in a direction uniform over the sphere; 2 straight radii, a body of
//!   8 to 16 radii, 2 straight radii to its end. Every vessel: tortuosity uniform in [0, 1]
//!   (arcs of 1.5 to 4 radii turning up to tortuosity × 75°, never tighter than 1.5 radii),
//!   taper uniform in [0, 30 %] of its radius along the body, a hairpin with probability 0.2 for
//!   the root and 0.12 for a daughter (60° to 130° within at most 3 radii, curvature radius at
//!   least 1.2 radii, as a carotid siphon).
//! * Places (where daughters leave a host): branches at the place 3..8 with weights 0.40, 0.20,
//!   0.13, 0.10, 0.09, 0.08; terminal (the host ends there: a Y, an n-furcation) with
//!   probability 0.4, else side branches off a host that goes on; the host drawn by radius; the
//!   anchors' spacing along the host 0 with probability 0.15, else uniform in [0.3, 3] host
//!   radii; per daughter a radius ratio uniform over [max(0.15, smallest / host radius), 1]
//!   (the main daughter of a terminal place at least 0.6), a branch angle uniform in [15°,
//!   170°], and for each daughter after the first an out-of-plane angle uniform in [0°, 90°]
//!   from the plane of the host's tangent and the first daughter (the branch angle then drawn
//!   within [α, 180° - α]). Each daughter leaves straight until clear of its host and siblings,
//!   then a body of 4 to 12 radii, then 2 straight radii to its end.
//! * Near passes: 0..3 drawn per tree (weights 0.3, 0.4, 0.2, 0.1); a daughter drawn for one is
//!   steered past another vessel: a cubic to a point whose wall gap is uniform between two
//!   cells and half the larger radius, arriving at a crossing angle uniform in [0°, 90°] (0: side
//!   by side), then straight on for 2 to 5 radii. Every pair of walls closer than the smaller
//!   radius is listed (steered or not).
//! * Stenoses: 0..3 per tree (weights 0.35, 0.35, 0.2, 0.1), area reduction uniform in [50 %,
//!   90 %], a raised-cosine notch 3 to 6 radii long, eccentricity uniform in [0, 1], on a vessel
//!   whose throat stays at or above the smallest radius. Aneurysms: 0..2 per tree (weights 0.5,
//!   0.35, 0.15), a ball of 0.8 to 2 vessel radii with a neck of 0.45 to 0.8 of it (at most 0.9
//!   of the vessel's radius) on a vessel's side.
//! * Ends: all open (0.5), all capped flat (0.3) or each capped with probability 1/2 (0.2).
//!
//! A draw that would bring two walls closer than two cells without blending them is drawn
//! again, and so is a daughter whose wall touches its host's or a sibling's past its junction
//! reach (where, at its branch angle, its wall has cleared its host's by the blend and the gap:
//! [`separation::junction_reach`]), or a sibling's past that sibling's reach: the truth's
//! junctions are then the only places where walls meet ([`separation::fused_runs`] measures
//! it on any tree). So the laid
//! distributions are the drawn ones thinned where the tree is crowded: `cargo bench --bench
//! trees` prints the laid bins over seeds 1-200.

pub mod centerline;
pub mod daughters;
pub mod features;
pub mod layout;
pub mod lumen;
pub mod model;
pub mod rng;
pub mod separation;
pub mod truth;

use crate::error::{Error, Result};
use crate::implicit_surface::{EndCircle, TriangulatedSurface};
use crate::input::Centerlines;
use crate::progress::Progress;
use indexmap::IndexMap;
use layout::{Layout, TreeDraws};
use lumen::{mesh_lumen, TreeLumen};
use model::NearPass;
use rng::SeededRng;
use serde_json::json;
use std::path::{Path, PathBuf};
use truth::{Manifest, Redraw};

/// Draws of a seed tried before giving up (none of seeds 1-200 needs more than a few).
pub const MAX_ATTEMPTS: u32 = 12;

/// A generated tree: its layout (the truth), its checked surface and its lumen function.
pub struct RandomTree {
    pub seed: u64,
    pub attempt: u32,
    pub redrawn: Vec<Redraw>,
    pub layout: Layout,
    /// Each end's vessel and circle: the inlet first, then the outlets.
    pub ends: Vec<(usize, EndCircle)>,
    pub surface: TriangulatedSurface,
    pub lumen: TreeLumen,
    pub near_passes: Vec<NearPass>,
}

/// Draws seed `seed`'s `attempt`-th tree (without its surface).
pub fn draw_layout(seed: u64, attempt: u32) -> Layout {
    let mut rng = SeededRng::new(seed, attempt);
    let draws = TreeDraws::draw(&mut rng);
    let mut layout = Layout::new(draws);
    layout.lay_root(&mut rng);
    layout.grow(&mut rng);
    layout.add_stenoses(&mut rng);
    layout.add_sacs(&mut rng);
    layout
}

impl RandomTree {
    /// The tree of `seed`: the first of its draws whose surface passes every check.
    pub fn generate(seed: u64, progress: &mut Progress) -> Result<Self> {
        let mut redrawn = Vec::new();
        for attempt in 0..MAX_ATTEMPTS {
            progress.stage(&format!("tree {seed}: drawing (attempt {})", attempt + 1));
            let mut layout = draw_layout(seed, attempt);
            let near_passes = layout.survey_near_passes();
            let ends = truth::end_circles(&layout);
            progress.stage(&format!("tree {seed}: surface"));
            let lumen = TreeLumen::new(&layout);
            let circles: Vec<EndCircle> = ends.iter().map(|(_, c)| *c).collect();
            match mesh_lumen(&lumen, &circles, 0) {
                Ok(surface) => {
                    return Ok(RandomTree { seed, attempt, redrawn, layout, ends, surface, lumen, near_passes })
                }
                Err(d) => redrawn.push(Redraw {
                    attempt,
                    reason: format!("{} near ({:.4}, {:.4}, {:.4}) mm", d.what, d.at.x, d.at.y, d.at.z),
                }),
            }
        }
        let last = redrawn.last().map_or(String::new(), |r| r.reason.clone());
        Err(Error::Geometry(format!(
            "random tree {seed}: every one of its {MAX_ATTEMPTS} draws failed the surface checks (the last: {last}); \
             try another seed"
        )))
    }

    /// File stem: `tree_<seed>`.
    pub fn name(&self) -> String {
        format!("tree_{}", self.seed)
    }

    /// The VMTK-style centerlines (see [`truth::centerlines`]).
    pub fn centerlines(&self) -> Result<Centerlines> {
        truth::centerlines(&self.layout, &self.lumen, &self.surface, &self.ends, &self.name()).ok_or_else(|| {
            Error::Geometry(format!("random tree {}: a centerline point has no closest surface point", self.seed))
        })
    }

    /// The manifest, naming the surface and centerline files.
    pub fn manifest(&self, surface_file: &str, centerlines_file: &str) -> Manifest {
        let layout = &self.layout;
        let junctions = truth::junctions(layout);
        let passes = truth::near_passes(layout, &self.near_passes);
        let (bins, extremes) = truth::bins(layout, &junctions, &passes);
        let (stenoses, aneurysms, hairpins) = truth::features(layout);
        let d = &layout.draws;
        let s = &self.surface;
        let open = self.ends.iter().filter(|(_, c)| !c.capped).count();
        let mut files = IndexMap::new();
        files.insert("surface", surface_file.to_string());
        files.insert("centerlines", centerlines_file.to_string());
        let draws = [
            ("target_ends", json!(d.target_ends)),
            ("ends", json!(self.ends.len())),
            ("radius_range", json!(d.radius_range)),
            ("smallest_radius_mm", json!(d.smallest_radius)),
            ("end_style", json!(d.end_style)),
            ("stenoses", json!(d.stenoses)),
            ("aneurysms", json!(d.aneurysms)),
            ("near_passes", json!(d.near_passes)),
            ("places_refused", json!(layout.places_refused)),
        ];
        let grid = [
            ("cell_size_mm", layout.h),
            ("cells_per_smallest_radius", layout::CELLS_PER_SMALLEST_RADIUS),
            ("gap_min_mm", layout.gap_min),
            ("extension_mm", layout.extension),
        ];
        let surface = [
            ("triangles", json!(s.triangles.len())),
            ("vertices", json!(s.vertices.len())),
            ("open_ends", json!(open)),
            ("capped_ends", json!(self.ends.len() - open)),
            ("euler_characteristic", json!(2 - open as i64)),
            ("genus", json!(0)),
            ("pieces", json!(1)),
            ("grid_cells", json!(s.stats.grid)),
            ("min_angle_deg", json!(s.stats.min_angle_deg)),
            ("min_edge_mm", json!(s.stats.min_edge)),
            ("max_edge_mm", json!(s.stats.max_edge)),
            ("max_vertex_offset_mm", json!(s.stats.max_vertex_offset)),
        ];
        Manifest {
            format: "vesselhex random tree",
            generator_version: truth::GENERATOR_VERSION,
            seed: self.seed,
            attempt: self.attempt,
            redrawn: self.redrawn.clone(),
            units: "mm",
            files,
            draws: draws.into_iter().collect(),
            grid: grid.into_iter().collect(),
            surface: surface.into_iter().collect(),
            bins,
            extremes,
            ends: self
                .ends
                .iter()
                .enumerate()
                .map(|(id, (vessel, c))| truth::EndTruth {
                    id,
                    vessel: *vessel,
                    role: if id == 0 { "inlet" } else { "outlet" },
                    kind: if c.capped { "capped" } else { "open" },
                    centre: [c.centre.x, c.centre.y, c.centre.z],
                    outward_normal: [c.outward.x, c.outward.y, c.outward.z],
                    radius_mm: c.radius,
                })
                .collect(),
            vessels: truth::vessels(layout, &self.ends),
            junctions,
            stenoses,
            aneurysms,
            hairpins,
            near_passes: passes,
        }
    }
}

/// The surface file's format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SurfaceFormat {
    /// Binary STL (f32 coordinates).
    Stl,
    /// VTK XML polydata (f64 coordinates).
    Vtp,
}

impl SurfaceFormat {
    pub fn extension(&self) -> &'static str {
        match self {
            SurfaceFormat::Stl => "stl",
            SurfaceFormat::Vtp => "vtp",
        }
    }
}

/// The files of tree `seed` in `dir`: `tree_<seed>.<stl|vtp>`, `tree_<seed>.json` (the
/// manifest), `tree_<seed>_centerlines.vtp`.
pub fn random_tree_paths(seed: u64, dir: &Path, format: SurfaceFormat) -> [PathBuf; 3] {
    generated_paths(&format!("tree_{seed}"), dir, format)
}

/// The files of a generated vessel named `stem` in `dir` (a tree or a network):
/// `<stem>.<stl|vtp>`, `<stem>.json` (the manifest), `<stem>_centerlines.vtp`.
pub fn generated_paths(stem: &str, dir: &Path, format: SurfaceFormat) -> [PathBuf; 3] {
    [
        dir.join(format!("{stem}.{}", format.extension())),
        dir.join(format!("{stem}.json")),
        dir.join(format!("{stem}_centerlines.vtp")),
    ]
}

/// What [`write_random_tree`] wrote.
pub struct WrittenTree {
    pub surface: PathBuf,
    pub manifest: PathBuf,
    pub centerlines: PathBuf,
    pub tree: RandomTree,
}

/// Generates tree `seed` and writes its surface, manifest and centerlines into `dir` (created if
/// needed), each file atomically and only once everything is computed. The bytes do not depend
/// on the thread count.
pub fn write_random_tree(seed: u64, dir: &Path, format: SurfaceFormat, progress: &mut Progress) -> Result<WrittenTree> {
    let tree = RandomTree::generate(seed, progress)?;
    progress.stage(&format!("tree {seed}: centerlines"));
    let centerlines = tree.centerlines()?;
    let [surface, manifest, centerline_path] = random_tree_paths(seed, dir, format);
    let file_name = |p: &Path| p.file_name().map_or(String::new(), |n| n.to_string_lossy().into_owned());
    let text = serde_json::to_string_pretty(&tree.manifest(&file_name(&surface), &file_name(&centerline_path)))
        .map_err(|e| Error::Geometry(format!("random tree {seed}: the manifest cannot be written: {e}")))?;
    progress.stage(&format!("tree {seed}: writing"));
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, "creating the output folder", e))?;
    let s = &tree.surface;
    match format {
        SurfaceFormat::Stl => {
            let header = format!("vesselhex random tree {seed}: mm, outward normals, {} ends", tree.ends.len());
            crate::synthetic::write_binary_stl(&surface, &header, &s.vertices, &s.triangles)?;
        }
        SurfaceFormat::Vtp => write_surface_vtp(&surface, &s.vertices, &s.triangles)?,
    }
    crate::writers::centerlines::write_vtp(&centerlines, 1.0, &centerline_path)?;
    crate::writers::write_atomic(&manifest, |w| {
        w.write_all(text.as_bytes())?;
        w.write_all(b"\n")
    })?;
    Ok(WrittenTree { surface, manifest, centerlines: centerline_path, tree })
}

/// A triangle surface as VTK XML polydata: Float64 points, Int64 connectivity and offsets,
/// base64 binary with UInt64 headers.
pub fn write_surface_vtp(path: &Path, vertices: &[nalgebra::Point3<f64>], triangles: &[[u32; 3]]) -> Result<()> {
    use base64::Engine;
    let encode = |bytes: Vec<u8>| {
        let mut block = (bytes.len() as u64).to_le_bytes().to_vec();
        block.extend(bytes);
        base64::engine::general_purpose::STANDARD.encode(block)
    };
    let points = encode(vertices.iter().flat_map(|p| [p.x, p.y, p.z]).flat_map(f64::to_le_bytes).collect());
    let connectivity = encode(triangles.iter().flatten().flat_map(|&v| i64::from(v).to_le_bytes()).collect());
    let offsets = encode((1..=triangles.len() as i64).flat_map(|i| (3 * i).to_le_bytes()).collect());
    crate::writers::write_atomic(path, |w| {
        writeln!(w, r#"<?xml version="1.0"?>"#)?;
        writeln!(w, r#"<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt64">"#)?;
        writeln!(w, "  <PolyData>")?;
        writeln!(
            w,
            r#"    <Piece NumberOfPoints="{}" NumberOfVerts="0" NumberOfLines="0" NumberOfStrips="0" NumberOfPolys="{}">"#,
            vertices.len(),
            triangles.len()
        )?;
        writeln!(
            w,
            r#"      <Points><DataArray type="Float64" NumberOfComponents="3" format="binary">{points}</DataArray></Points>"#
        )?;
        writeln!(
            w,
            r#"      <Polys><DataArray type="Int64" Name="connectivity" format="binary">{connectivity}</DataArray>"#
        )?;
        writeln!(w, r#"        <DataArray type="Int64" Name="offsets" format="binary">{offsets}</DataArray></Polys>"#)?;
        writeln!(w, "    </Piece>\n  </PolyData>\n</VTKFile>")
    })
}
