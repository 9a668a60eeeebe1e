//! Centerlines from the lumen surface alone: the vessel's ends, the inlet, and one polyline
//! from the inlet to every outlet carrying the maximal inscribed sphere radius, written as
//! VMTK-compatible polydata ([`crate::writers::centerlines::write_vtp`]) or handed straight to the mesher.
//!
//! # Method: shortest paths through maximal balls
//!
//! VMTK's centerlines are paths of minimal cost `1/R` through the Voronoi diagram of the surface
//! points, whose vertices are centres of maximal empty balls (the medial axis) with `R` their
//! radius. We keep that principle, which centres the line by construction and gives the radius
//! for free:
//!
//! * **Medial balls from the inner Voronoi diagram** (`sampling`, `voronoi`): the surface, closed
//!   by a fan on every boundary loop, is resampled at a spacing set by the local radius, so that
//!   thin vessels and coarse triangles alike get enough points; their 3D Delaunay tessellation
//!   (Qhull's C library, vendored and compiled with the `cc` crate, see `qhull`) gives a ball per
//!   tetrahedron, its circumsphere, kept when its centre passes VMTK's test of an internal
//!   tetrahedron (inside the tangent planes at the four corners). Tetrahedra sharing a face give
//!   a link when their balls overlap, so every link lies in the union of two empty balls, i.e.
//!   inside the lumen. Dijkstra with VMTK's cost `length x mean(1/R)` from the inlet gives all
//!   the paths at once, sharing the inlet part exactly as VMTK's do.
//!
//! The path through ball centres zig-zags at the scale of the sample spacing, so it is
//! resampled at a tenth of the radius and smoothed with a Gaussian in arc length of width
//! 0.25 r (corner cutting in a bend of radius `Rb` is about `(0.25 r)^2 / 2Rb`, well below
//! 1 % of r on every vessel we have). Where the depth is nearly flat across a section, the path
//! is then moved within its normal plane to the section's deepest point (`centring`). The radius
//! stored is the true distance from each point to the (opened) surface's triangles, computed with
//! the BVH of [`LumenSurface`].
//!
//! A harmonic field on the surface (level-set rings) was the alternative; its ring centroids
//! are not the centres of inscribed spheres (biased in bends and at junctions), its radius is
//! an equivalent one, and several outlets need one field each or a Reeb graph. The ball graph
//! handles any number of outlets with one Dijkstra.
//!
//! # Ends
//!
//! Triangles are first wound consistently (inward and outward triangles mixed in one file are
//! repaired) and oriented by the sign of the enclosed volume. Flat caps are taken off: the
//! tag values of a cell array (`ModelFaceID`) whose triangles form a flat disc, or else planar
//! regions with a sharp rim. Every boundary loop of what remains is an end, its centre the
//! edge-length weighted loop centre (VMTK's cap centre) and its size the equivalent radius
//! sqrt(area / pi), unless it is a hole in the wall: a loop is judged against the vessel around
//! it, not against the other loops (a side branch's end can be smaller than a defect in the
//! aorta): the maximal ball tangent to the loop's plane at its centre, on the lumen's side, is
//! the end section's own inscribed ball at an end (radius about the loop's), the vessel's ball
//! behind a hole (much larger than the loop). Rounded caps have neither: the user gives points
//! on or near them (`--ends`), snapped to the surface and moved inward up to the medial axis
//! (the ball stops growing there), whose ball becomes the end. The inlet is the largest end, or
//! the end nearest a point.

mod bridges;
mod centring;
mod ends;
pub mod loops;
mod medial;
mod qhull;
mod rounded;
mod sampling;
mod split;

mod voronoi;

pub use ends::{find_caps, names_of_ends, Cap, EndKind, Hole, InletChoice, VesselEnd, CAP_SPAN, END_SPAN};
pub use split::branch_split;

use crate::data::error::{Error, Result};
use crate::geometry::surface::{LumenSurface, SolidSurface};
use crate::io::input::{topology, CenterlinePolyline, Centerlines, NamedCap, TriangleSurface};
use indexmap::IndexMap;
use medial::{Ball, BallGraph};
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

/// Output points are spaced by this fraction of the path's small radii.
const STEP_FRACTION: f64 = 0.1;
/// Gaussian smoothing width, as a fraction of the local radius.
const SMOOTH_SIGMA: f64 = 0.25;
/// A given end point within this many end radii of a found end's centre names that end.
const SAME_END: f64 = 1.5;
/// A given end point is moved inward from the surface in steps of this fraction of the distance
/// to the surface reached so far (and at least half an edge of the triangle it snapped to) ...
const MARCH_STEP: f64 = 0.1;
/// ... while that distance grows by at least this fraction of the step (1 when moving straight
/// away from a wall, below 0 once the step crosses the medial axis).
const MARCH_GROWTH: f64 = 0.5;
/// ... or stops after this many steps without such growth.
const MARCH_PATIENCE: usize = 4;
/// A given end point outside the surface by more than this many vessel radii there is refused.
const FAR_FROM_SURFACE: f64 = 2.0;
/// A blunt face within this many radii (its own or an end's) of an end found is that end's tip.
const BLUNT_SAME_END: f64 = 3.0;
/// A cap of this name is the inlet (unless `--inlet` chooses another end); a cap whose name
/// starts with it and `_` (`inlet_svc`) is an inlet too.
pub const INLET_NAME: &str = "inlet";

/// Whether a cap's name makes its end an inlet (see [`INLET_NAME`]).
pub fn is_inlet_name(name: &str) -> bool {
    name.strip_prefix(INLET_NAME).is_some_and(|rest| rest.is_empty() || rest.starts_with('_'))
}
/// Two largest ends closer than this ratio make the automatic inlet choice worth a note.
const AMBIGUOUS_INLET: f64 = 0.9;

/// What the user tells the extraction (lengths in millimetres).
#[derive(Debug, Clone)]
pub struct ExtractOptions {
    pub inlet: InletChoice,
    /// Extra end points (rounded caps), snapped to the surface.
    pub ends: Vec<Point3<f64>>,
    /// Points near the domes of saccular aneurysms the search does not take as sacs: ends of kind
    /// [`EndKind::Sac`] (meshed as blind branches closed by a dome).
    pub sacs: Vec<Point3<f64>>,
    /// Caps given in files of their own (see [`crate::io::input::read_surface_parts`]): each joined
    /// one (tagged) is an end whatever its shape, in place of the flat caps the search would
    /// find, and every one names the end it closes or covers.
    pub caps: Vec<NamedCap>,
    /// Names of caps the user flags as inlets (`--inlet NAME`), in the order given: with the
    /// inlet [`InletChoice::Largest`], the first that closes an end is the inlet.
    pub inlet_names: Vec<String>,
}

impl Default for ExtractOptions {
    fn default() -> Self {
        ExtractOptions { inlet: InletChoice::Largest, ends: vec![], sacs: vec![], caps: vec![], inlet_names: vec![] }
    }
}

/// The centerlines and how they were found.
#[derive(Debug, Clone)]
pub struct Extraction {
    /// One polyline per outlet, from the inlet, with `MaximumInscribedSphereRadius` and
    /// `CenterlineIds`; millimetres.
    pub centerlines: Centerlines,
    pub ends: Vec<VesselEnd>,
    /// Index of the inlet in `ends`; the polylines go to the other ends in order.
    pub inlet: usize,
    /// The name of each end a cap given names (see [`ExtractOptions::caps`]), in `ends`' order.
    pub end_names: Vec<Option<String>>,
    /// Boundary loops left out as holes in the wall (too small for the vessel around them).
    pub holes: Vec<Hole>,
    /// Facts worth telling the user (repairs, caps removed, ambiguous inlet).
    pub notes: Vec<String>,
    /// Where the surface's loops were cut open to find its centerlines (see [`loops`]): the two
    /// polylines ending at each cut, one from either side, are one vessel. Not in `ends`.
    pub loop_cuts: Vec<loops::LoopCut>,
}

/// Computes the centerlines of a lumen surface (millimetres). Never panics on bad geometry:
/// failures (too few ends, an end not connected to the inlet) are errors naming the fix. A
/// surface with loops is cut open at one place per loop first (see [`loops`]).
pub fn extract_centerlines(surface: &TriangleSurface, options: &ExtractOptions) -> Result<Extraction> {
    let loops = topology::handles(&surface.triangles).unwrap_or(0);
    if loops == 0 {
        return extract_tree(surface, options, &[]);
    }
    let mut notes = vec![];
    let mut search = EndSearch::new(surface, &options.caps, &[], &mut notes)?;
    search.add_given(&options.ends, EndKind::Given)?;
    search.join_parts();
    let end_names = ends::names_of_ends(&search.found, &options.caps).map_err(|e| Error::input(&surface.source, e))?;
    let inlet = match (options.inlet, named_inlet(&search.found, &end_names, &options.inlet_names)) {
        (InletChoice::Largest, Some(k)) => k,
        (choice, _) => ends::choose_inlet(&search.found, choice),
    };
    let inlet_node = search.end_nodes[inlet];
    let (opened, cuts) = loops::open_loops(surface, &search.graph, inlet_node, &search.lumen, loops)
        .map_err(|e| Error::input(&surface.source, e))?;
    // The inlet chosen on the whole surface: a cut's end may be wider than it.
    let options = ExtractOptions { inlet: InletChoice::Nearest(search.found[inlet].centre), ..options.clone() };
    let mut extraction = extract_tree(&opened, &options, &cuts)?;
    extraction.take_out_cut_ends(&cuts).map_err(|e| Error::input(&surface.source, e))?;
    extraction.notes.push(format!(
        "the surface has {loops} loop(s): cut open at {} to find the centerlines, and joined again in the mesh",
        cuts.iter()
            .map(|c| format!("({:.3}, {:.3}, {:.3}) mm", c.centre.x, c.centre.y, c.centre.z))
            .collect::<Vec<_>>()
            .join(", ")
    ));
    extraction.loop_cuts = cuts;
    Ok(extraction)
}

impl Extraction {
    /// Takes the two ends each cut opened out of the ends (the two nearest open ends near it,
    /// see [`loops::near_a_cut`]).
    fn take_out_cut_ends(&mut self, cuts: &[loops::LoopCut]) -> std::result::Result<(), String> {
        for cut in cuts {
            let gap = |k: usize| (self.ends[k].centre - cut.centre).norm();
            let mut at_cut: Vec<usize> = (0..self.ends.len())
                .filter(|&k| {
                    self.ends[k].kind == EndKind::Open
                        && loops::near_a_cut(std::slice::from_ref(cut), &self.ends[k].centre)
                })
                .collect();
            at_cut.sort_by(|&a, &b| gap(a).total_cmp(&gap(b)).then(a.cmp(&b)));
            at_cut.truncate(2);
            if at_cut.len() != 2 || at_cut.contains(&self.inlet) {
                return Err(format!(
                    "the loop cut open at ({:.3}, {:.3}, {:.3}) mm gave {} end(s) there, not 2: the loop cannot be joined \
                     again; give centerlines cut open on a vessel of the loop, with the cut point as \
                     centerline.loop_cuts_mm",
                    cut.centre.x,
                    cut.centre.y,
                    cut.centre.z,
                    at_cut.len()
                ));
            }
            at_cut.sort_unstable();
            for &k in at_cut.iter().rev() {
                self.ends.remove(k);
                self.end_names.remove(k);
                if self.inlet > k {
                    self.inlet -= 1;
                }
            }
        }
        Ok(())
    }
}

/// [`extract_centerlines`] on a surface without loops: as it came, or opened at `cuts`.
fn extract_tree(surface: &TriangleSurface, options: &ExtractOptions, cuts: &[loops::LoopCut]) -> Result<Extraction> {
    let mut notes = vec![];
    let mut search = EndSearch::new(surface, &options.caps, cuts, &mut notes)?;
    search.add_given(&options.ends, EndKind::Given)?;
    search.add_given(&options.sacs, EndKind::Sac)?;
    // Each search below grows from the paths to the ends found before it, so the parts of the
    // ball graph that hold those ends are joined through the lumen first (see `bridges`).
    search.join_parts();
    search.add_rounded();
    search.join_parts();
    search.add_blunt()?;
    search.join_parts();
    search.add_sacs();
    search.join_parts();
    let EndSearch { graph, found, end_nodes, lumen, holes, .. } = search;
    if found.len() < 2 {
        return Err(Error::input(
            &surface.source,
            format!(
                "found {} vessel end(s) ({} given with --ends), a centerline needs at least 2: the surface holds one \
                 vessel end or none that vesselhex can recognise (open boundary, flat cap or rounded tip). Give a \
                 point near every end not found, e.g. --ends x,y,z --ends x,y,z (in the surface's units)",
                found.len(),
                options.ends.len()
            ),
        ));
    }
    let end_names = ends::names_of_ends(&found, &options.caps).map_err(|e| Error::input(&surface.source, e))?;
    let named_inlet = named_inlet(&found, &end_names, &options.inlet_names);
    let inlet = match (options.inlet, named_inlet) {
        (InletChoice::Largest, Some(k)) => k,
        (choice, _) => ends::choose_inlet(&found, choice),
    };
    if options.inlet == InletChoice::Largest && named_inlet.is_none() {
        notes.extend(ambiguous_inlet(&found));
    }
    let polylines = trace(&graph, &found, &end_nodes, inlet, &lumen)?;
    let centerlines = Centerlines { polylines, source: surface.source.clone() };
    Ok(Extraction { centerlines, ends: found, inlet, end_names, holes, notes, loop_cuts: vec![] })
}

/// The end a cap's name makes the inlet, unless the user chose another by a point: the first
/// cap flagged by name (`inlet_names`), else the cap named [`INLET_NAME`], else the largest end
/// whose cap is named as an inlet (`inlet_<x>`).
fn named_inlet(found: &[VesselEnd], end_names: &[Option<String>], inlet_names: &[String]) -> Option<usize> {
    let named = |want: &str| end_names.iter().position(|n| n.as_deref() == Some(want));
    let inlet_like = (0..found.len()).filter(|&k| end_names[k].as_deref().is_some_and(is_inlet_name));
    inlet_names
        .iter()
        .find_map(|want| named(want))
        .or_else(|| named(INLET_NAME))
        .or_else(|| inlet_like.max_by(|&a, &b| found[a].radius.total_cmp(&found[b].radius).then(b.cmp(&a))))
}

/// A note when the two largest ends have nearly the same radius (see [`AMBIGUOUS_INLET`]).
fn ambiguous_inlet(found: &[VesselEnd]) -> Option<String> {
    let mut radii: Vec<f64> = found.iter().map(|e| e.radius).collect();
    radii.sort_by(|a, b| b.total_cmp(a));
    (radii[1] > AMBIGUOUS_INLET * radii[0]).then(|| {
        format!(
            "the two largest ends have nearly the same radius ({:.3} and {:.3} mm): the inlet was taken as the \
             largest; give --inlet x,y,z to choose",
            radii[0], radii[1]
        )
    })
}

/// The medial axis of a surface and the ends found on it so far, each a node of the graph.
struct EndSearch {
    graph: BallGraph,
    found: Vec<VesselEnd>,
    end_nodes: Vec<u32>,
    /// The surface the radii are measured on (cut caps taken off), and its inward normals.
    lumen: LumenSurface,
    inward: Vec<Vector3<f64>>,
    holes: Vec<Hole>,
    /// Flat faces with a rounded rim, ends only where the paths leave them uncovered.
    blunt: Vec<Cap>,
    /// The surface's triangles (wound consistently), and whether each is an end's face, left
    /// out of the surface the radii are measured on.
    triangles: Vec<[u32; 3]>,
    in_cap: Vec<bool>,
    /// The Delaunay tetrahedra of the closed surface's samples, to join the graph's parts that
    /// hold ends (`None` when the closed surface is not a manifold one can tell inside from).
    tets: Option<bridges::LumenTets>,
}

impl EndSearch {
    /// The medial axis, and the ends with a boundary: loops and cut flat caps that span the
    /// vessel behind them.
    ///
    /// The two ends each of `cuts` opened (see [`loops::near_a_cut`]) are ends whatever the
    /// ball behind them, and never merged as pieces of another end: they face each other across
    /// a gap of about a diameter.
    fn new(
        surface: &TriangleSurface,
        given_caps: &[NamedCap],
        cuts: &[loops::LoopCut],
        notes: &mut Vec<String>,
    ) -> Result<EndSearch> {
        let (source, vertices) = (&surface.source, &surface.vertices);
        // Wound consistently for the closing below. Callers pass a surface `clean_surface` has
        // already wound (and reported): nothing is left to flip.
        let mut triangles = surface.triangles.clone();
        topology::orient_consistently(&mut triangles);
        // The surface closed by a fan on every boundary loop (ends and holes alike) and facing
        // out: its inner Voronoi diagram is the medial axis.
        let loops = topology::boundary_loops(&triangles);
        let sign = if topology::signed_volume6(vertices, &triangles, &loops) > 0.0 { -1.0 } else { 1.0 };
        let (closed_vertices, closed_triangles) = topology::close_with_caps(vertices, &triangles, &loops, sign);
        let (samples, normals) = sampling::resample(&closed_vertices, &closed_triangles);
        let (mut graph, tessellation, node_of) =
            voronoi::medial_graph(&samples, &normals).map_err(|e| Error::input(source, e))?;
        let solid = SolidSurface::new(&closed_vertices, &closed_triangles);
        let tets = solid.map(|solid| bridges::LumenTets::new(tessellation, node_of, samples, solid));

        let poles = medial::PoleIndex::new(&graph);
        let (mut found, mut holes) = ends::loop_ends(vertices, &loops, |c, radius| poles.pole(c, 0.5 * radius).radius);
        // A cut's two loops are ends by construction, whatever the ball behind them: beside a
        // junction that ball is the junction's, larger than the cut vessel, as behind a hole.
        let at_a_cut = |c: &Point3<f64>| loops::near_a_cut(cuts, c);
        for hole in holes.iter().filter(|h| at_a_cut(&h.centre)) {
            found.push(VesselEnd { centre: hole.centre, radius: hole.radius, kind: EndKind::Open });
        }
        holes.retain(|h| !at_a_cut(&h.centre));
        notes.extend(holes.iter().map(|h| {
            format!(
                "a boundary loop at ({:.3}, {:.3}, {:.3}) mm of radius {:.3} mm was left out as a hole in the wall \
                 (the vessel there has radius {:.3} mm)",
                h.centre.x, h.centre.y, h.centre.z, h.radius, h.vessel_radius
            )
        }));
        let tags = surface.triangle_tags.as_ref().map(|(_, t)| t.as_slice());
        // Flat caps: cut ones (a sharp rim) that span the vessel now; blunt ones (a rounded rim)
        // later, in `add_blunt`. Caps given in files of their own are the caps, whatever their
        // shape.
        let (caps, blunt): (Vec<Cap>, Vec<Cap>) = match tags.filter(|_| !given_caps.is_empty()) {
            Some(tags) => (ends::tagged_caps(vertices, &triangles, tags, given_caps), vec![]),
            None => ends::find_caps(vertices, &triangles, tags)
                .into_iter()
                .filter(|cap| cap.end.radius >= CAP_SPAN * poles.pole(&cap.end.centre, 0.5 * cap.end.radius).radius)
                .partition(|cap| cap.sharp_rim),
        };
        if !caps.is_empty() {
            notes.push(format!("{} flat caps taken off", caps.len()));
        }
        let mut in_cap = vec![false; triangles.len()];
        for cap in &caps {
            cap.triangles.iter().for_each(|&t| in_cap[t as usize] = true);
            found.push(cap.end);
        }
        let at_cut = |e: &VesselEnd| loops::near_a_cut(cuts, &e.centre);
        found = ends::merge_nested(found, at_cut);
        let open: Vec<[u32; 3]> = triangles.iter().zip(&in_cap).filter(|(_, c)| !**c).map(|(t, _)| *t).collect();
        let inward = topology::vertex_normals(vertices, &open).into_iter().map(|n| n * sign).collect();
        let lumen = LumenSurface::from_parts(vertices.clone(), open, source.clone())?;
        let end_nodes = found.iter().map(|e| graph.add_end(Ball { centre: e.centre, radius: e.radius })).collect();
        Ok(EndSearch { graph, found, end_nodes, lumen, inward, holes, blunt, triangles, in_cap, tets })
    }

    /// Joins the parts of the ball graph that hold the ends found so far, through the lumen (see
    /// `bridges`): the paths to every end then run inside the lumen whatever its medial balls.
    fn join_parts(&mut self) {
        if let Some(tets) = &self.tets {
            bridges::join_ends(&mut self.graph, tets, &self.end_nodes);
        }
    }

    /// The points given (`--ends`, or `--sacs` with `kind` sac) that name no end found: the
    /// inscribed balls under them. A sac given where an end was found makes that end a sac.
    fn add_given(&mut self, points: &[Point3<f64>], kind: EndKind) -> Result<()> {
        let (lo, hi) = self.lumen.bounding_box();
        for p in points {
            if let Some(end) = self.found.iter_mut().find(|e| (e.centre - p).norm() < SAME_END * e.radius) {
                if kind == EndKind::Sac {
                    end.kind = kind;
                }
                continue;
            }
            let ball = given_end_ball(p, &self.lumen, &self.inward, (hi - lo).norm())?;
            self.found.push(VesselEnd { centre: ball.centre, radius: ball.radius, kind });
            self.end_nodes.push(self.graph.add_end(ball));
        }
        Ok(())
    }

    /// Rounded ends: the vessels the paths between the ends so far do not reach (see `rounded`).
    fn add_rounded(&mut self) {
        let beside_open_ends = self.found.iter().any(|e| e.kind == EndKind::Open);
        let covered = paths_between(&self.graph, &self.end_nodes);
        let clearance = |p: &Point3<f64>| self.lumen.closest(p).distance;
        let start_alone = self.end_nodes.is_empty();
        for node in rounded::rounded_ends(&self.graph, &covered, start_alone, beside_open_ends, &clearance) {
            let ball = self.graph.nodes[node as usize];
            self.found.push(VesselEnd { centre: ball.centre, radius: ball.radius, kind: EndKind::Dome });
            self.end_nodes.push(node);
        }
    }

    /// Saccular aneurysms: pockets beside the paths to every end that reach far beyond the
    /// vessel they open from (see `rounded::sac_ends`). Each becomes an end of kind
    /// [`EndKind::Sac`], meshed as a blind branch to its dome.
    fn add_sacs(&mut self) {
        let covered = paths_between(&self.graph, &self.end_nodes);
        // Inside the surface closed across its open ends and cut caps: the winding number of the
        // open surface is about 1 there (its sign the triangles' facing), below a half beyond
        // an opening.
        let in_lumen = |p: &Point3<f64>| self.lumen.winding_number(p).abs() >= 0.5;
        let clearance = |p: &Point3<f64>| self.lumen.closest(p).distance;
        for node in rounded::sac_ends(&self.graph, &covered, &in_lumen, &clearance) {
            let ball = self.graph.nodes[node as usize];
            self.found.push(VesselEnd { centre: ball.centre, radius: ball.radius, kind: EndKind::Sac });
            self.end_nodes.push(node);
        }
    }

    /// Blunt ends: a flat face with a rounded rim that the paths to every other end leave
    /// beyond their balls (a short, wide vessel whose tip the rounded-end search does not take
    /// for a vessel); a flat patch of a wall lies against those balls.
    ///
    /// The end is the face's centre, as a cut cap's, with the radius of the inscribed ball under
    /// the face (the vessel's: the face stops short of the wall at its rounded rim). The inscribed
    /// ball itself lies a vessel radius inside the face, and a short trunk's ball reaches its
    /// branches (sphinxsys_pulmonary_bifurcation: the inlet's ball, radius 15.8 mm, lies 16 mm
    /// inside the face, where the paths to both outlets part), so the centerline must run on to the
    /// face. Like a cut cap's, the face is then left out of the surface the radii are measured on:
    /// the radius there is the rim's distance, not nothing.
    fn add_blunt(&mut self) -> Result<()> {
        let covered = paths_between(&self.graph, &self.end_nodes);
        let mut taken = false;
        for cap in std::mem::take(&mut self.blunt) {
            let gap = covered
                .iter()
                .map(|&n| self.graph.nodes[n as usize])
                .map(|b| (b.centre - cap.end.centre).norm() - b.radius);
            let beyond = gap.fold(f64::INFINITY, f64::min) > 0.5 * cap.end.radius;
            // An end found nearby (a dome's ball lies a radius or two inside its tip) is this one.
            let near =
                |e: &VesselEnd| (e.centre - cap.end.centre).norm() < BLUNT_SAME_END * e.radius.max(cap.end.radius);
            if beyond && !self.found.iter().any(near) {
                let vessel = self.graph.pole(&cap.end.centre, 0.5 * cap.end.radius).radius;
                let end = VesselEnd { radius: vessel, ..cap.end };
                self.end_nodes.push(self.graph.add_end(Ball { centre: end.centre, radius: end.radius }));
                self.found.push(end);
                cap.triangles.iter().for_each(|&t| self.in_cap[t as usize] = true);
                taken = true;
            }
        }
        if taken {
            let open = self.triangles.iter().zip(&self.in_cap).filter(|(_, c)| !**c).map(|(t, _)| *t).collect();
            self.lumen = LumenSurface::from_parts(self.lumen.vertices.clone(), open, self.lumen.source.clone())?;
        }
        Ok(())
    }
}

/// The nodes on the shortest paths from the first of `ends` to the others (all of them when it
/// is alone; the largest ball when there is none): what the centerlines found so far cover.
fn paths_between(graph: &BallGraph, ends: &[u32]) -> Vec<u32> {
    let Some(&first) = ends.first() else {
        let largest = (0..graph.nodes.len() as u32)
            .max_by(|&a, &b| graph.nodes[a as usize].radius.total_cmp(&graph.nodes[b as usize].radius).then(b.cmp(&a)));
        return largest.into_iter().collect();
    };
    let (prev, _) = graph.shortest_paths(first);
    let mut on_paths = vec![first];
    for &e in &ends[1..] {
        let mut at = e;
        while at != u32::MAX && at != first {
            on_paths.push(at);
            at = prev[at as usize];
        }
    }
    on_paths
}

/// One smoothed polyline from the inlet to every other end, along the least-cost paths.
///
/// The paths form a tree (Dijkstra's from the inlet): they share their nodes up to where the
/// medial axis branches. Each stretch between branch nodes is smoothed once, its ends held, so
/// the polylines coincide exactly up to the branch node and part there, as VMTK's do; smoothed
/// one by one, two paths would start to part a smoothing width before it.
fn trace(
    graph: &BallGraph,
    ends: &[VesselEnd],
    end_nodes: &[u32],
    inlet: usize,
    lumen: &LumenSurface,
) -> Result<Vec<CenterlinePolyline>> {
    let (prev, _) = graph.shortest_paths(end_nodes[inlet]);
    let mut chains = vec![];
    for (k, (end, &node)) in ends.iter().zip(end_nodes).enumerate().filter(|(k, _)| *k != inlet) {
        let mut chain = vec![node];
        while let Some(&last) = chain.last() {
            match prev[last as usize] {
                u32::MAX => break,
                p => chain.push(p),
            }
        }
        if chain.last() != Some(&end_nodes[inlet]) {
            return Err(Error::input(
                &lumen.source,
                format!(
                    "end {k} at ({:.3}, {:.3}, {:.3}) mm is not connected to the inlet through the lumen (a pinched or \
                     self-intersecting surface?)",
                    end.centre.x, end.centre.y, end.centre.z
                ),
            ));
        }
        chain.reverse();
        chains.push(chain);
    }
    // Branch nodes: where the chains through a node go on to different nodes (or one ends).
    let mut next_of: std::collections::HashMap<u32, Vec<u32>> = std::collections::HashMap::new();
    for chain in &chains {
        for w in chain.windows(2) {
            let next = next_of.entry(w[0]).or_default();
            if !next.contains(&w[1]) {
                next.push(w[1]);
            }
        }
        next_of.entry(chain[chain.len() - 1]).or_default().push(u32::MAX);
    }
    let branches_at = |n: u32| next_of.get(&n).is_some_and(|v| v.len() > 1);
    // Each stretch between two branch nodes, smoothed once: its points and radii.
    type Stretch = (Vec<Point3<f64>>, Vec<f64>);
    let mut smoothed: std::collections::HashMap<(u32, u32), Stretch> = std::collections::HashMap::new();
    let mut polylines = vec![];
    for chain in &chains {
        let (mut points, mut radii): (Vec<Point3<f64>>, Vec<f64>) = (vec![], vec![]);
        let mut start = 0;
        for i in 1..chain.len() {
            if i + 1 < chain.len() && !branches_at(chain[i]) {
                continue;
            }
            let stretch = smoothed.entry((chain[start], chain[i])).or_insert_with(|| {
                let balls: Vec<Ball> = chain[start..=i].iter().map(|&n| graph.nodes[n as usize]).collect();
                smooth_path(&balls, lumen)
            });
            let skip = usize::from(!points.is_empty());
            points.extend_from_slice(&stretch.0[skip..]);
            radii.extend_from_slice(&stretch.1[skip..]);
            start = i;
        }
        let mut cell_tags = IndexMap::new();
        cell_tags.insert("CenterlineIds".to_string(), polylines.len() as i64);
        polylines.push(CenterlinePolyline { points, radii: Some(radii), normals: None, cell_tags });
    }
    Ok(polylines)
}

/// The end ball of a point given by the user: the point is snapped to the surface, then moved
/// inward along the surface normal while its distance to the surface keeps growing, i.e. up to
/// the medial axis. So a point at the very tip of a rounded cap (or a little outside it, or a
/// little inside) gives the inscribed ball under the cap, not the tiny ball of a bump on the
/// tip, which no larger ball overlaps. Fails when the point lies outside the surface by more than
/// [`FAR_FROM_SURFACE`] times the radius of that ball (a point given in the wrong unit, or off
/// the vessel).
fn given_end_ball(p: &Point3<f64>, lumen: &LumenSurface, inward: &[Vector3<f64>], diagonal: f64) -> Result<Ball> {
    let source = &lumen.source;
    let hit = lumen.closest(p);
    let tri = lumen
        .triangles
        .get(hit.triangle as usize)
        .ok_or_else(|| Error::input(source, "the surface has no triangles"))?;
    let corners = tri.map(|v| lumen.vertices[v as usize]);
    let normal = tri.iter().map(|&v| inward[v as usize]).sum::<nalgebra::Vector3<f64>>().try_normalize(0.0);
    let edge = (0..3).map(|k| (corners[(k + 1) % 3] - corners[k]).norm()).fold(0.0, f64::max);
    let mut best = Ball { centre: hit.point, radius: 0.0 };
    if let Some(n) = normal {
        // Gradient ascent of the distance to the surface: each step goes straight away from the
        // nearest surface point (the inward normal there). It ends when the ball has not grown
        // for a few steps: the steps then cross the medial axis back and forth. A few steps of
        // patience carry it past small bumps of the surface (a tip vertex standing out of its
        // cap has only a tiny ball).
        let (mut x, mut direction, mut stalled) = (hit.point, n, 0);
        let mut travelled = 0.0;
        while travelled < diagonal && stalled < MARCH_PATIENCE {
            let step = (MARCH_STEP * best.radius).max(0.5 * edge).max(1e-9 * diagonal);
            x += direction * step;
            travelled += step;
            let near = lumen.closest(&x);
            if near.distance >= best.radius + MARCH_GROWTH * step {
                best = Ball { centre: x, radius: near.distance };
                stalled = 0;
            } else {
                stalled += 1;
            }
            match (x - near.point).try_normalize(0.0) {
                Some(d) => direction = d,
                None => break,
            }
        }
    }
    let at = format!("the end point ({:.3}, {:.3}, {:.3}) mm", p.x, p.y, p.z);
    if best.radius <= 0.0 || !best.radius.is_finite() {
        return Err(Error::input(
            source,
            format!(
                "{at}: no inscribed ball found inward of the surface point ({:.3}, {:.3}, {:.3}) nearest to it; give a \
                 point on or just outside a rounded cap",
                hit.point.x, hit.point.y, hit.point.z
            ),
        ));
    }
    let outside = normal.is_some_and(|n| (p - hit.point).dot(&n) < 0.0);
    if outside && hit.distance > FAR_FROM_SURFACE * best.radius {
        return Err(Error::input(
            source,
            format!(
                "{at} lies {:.3} mm outside the surface, more than {FAR_FROM_SURFACE} times the vessel's radius there \
                 ({:.3} mm): give a point on the tip of the rounded cap or just outside it, in the surface's units \
                 (--units)",
                hit.distance, best.radius
            ),
        ));
    }
    Ok(best)
}

/// Resamples a chain of balls at [`STEP_FRACTION`] of its small radii, smooths it with a
/// Gaussian of width [`SMOOTH_SIGMA`] x radius in arc length (window kept symmetric, so the end
/// points stay put), centres it on the ridge of the lumen's depth (see `centring`), and
/// measures the radius as the distance to the surface.
fn smooth_path(balls: &[Ball], lumen: &LumenSurface) -> (Vec<Point3<f64>>, Vec<f64>) {
    let mut s = vec![0.0];
    for w in balls.windows(2) {
        s.push(s[s.len() - 1] + (w[1].centre - w[0].centre).norm());
    }
    let length = s[s.len() - 1];
    let mut radii: Vec<f64> = balls.iter().map(|b| b.radius).collect();
    radii.sort_by(f64::total_cmp);
    // The path's small radii set the step, but not the few tiny balls by an end's rim.
    let small = radii[radii.len() / 10].max(0.25 * radii[radii.len() / 2]);
    let n = ((length / (STEP_FRACTION * small)).ceil() as usize).clamp(1, 100_000);
    let at = |t: f64| {
        let i = s.partition_point(|&x| x <= t).clamp(1, s.len().max(2) - 1) - 1;
        if i + 1 >= balls.len() {
            return (balls[balls.len() - 1].centre, balls[balls.len() - 1].radius);
        }
        let w = if s[i + 1] > s[i] { ((t - s[i]) / (s[i + 1] - s[i])).clamp(0.0, 1.0) } else { 0.0 };
        (
            balls[i].centre + (balls[i + 1].centre - balls[i].centre) * w,
            balls[i].radius * (1.0 - w) + balls[i + 1].radius * w,
        )
    };
    let samples: Vec<(f64, Point3<f64>, f64)> = (0..=n)
        .map(|k| {
            let t = length * k as f64 / n as f64;
            let (p, r) = at(t);
            (t, p, r)
        })
        .collect();
    let s: Vec<f64> = samples.iter().map(|q| q.0).collect();
    let radii: Vec<f64> = samples.iter().map(|q| q.2).collect();
    let along: Vec<Vector3<f64>> = samples.iter().map(|q| q.1.coords).collect();
    let smoothed: Vec<Point3<f64>> = gaussian(&s, &along, &radii).into_iter().map(Point3::from).collect();
    // The shifts onto the depth's ridge are smoothed as the path was: the deepest point of each
    // section moves with the triangles' facets.
    let shifts = gaussian(&s, &centring::ridge_shifts(&smoothed, &s, lumen), &radii);
    let smoothed: Vec<Point3<f64>> = smoothed.iter().zip(&shifts).map(|(p, d)| p + d).collect();
    let radii = smoothed.par_iter().map(|p| lumen.closest(p).distance).collect();
    (smoothed, radii)
}

/// `values` at arc lengths `s` smoothed by a Gaussian in arc length of width [`SMOOTH_SIGMA`]
/// times `radii`, its window kept symmetric and so shrinking to nothing at either end (the end
/// values stay put).
fn gaussian(s: &[f64], values: &[Vector3<f64>], radii: &[f64]) -> Vec<Vector3<f64>> {
    let length = s[s.len() - 1];
    (0..s.len())
        .into_par_iter()
        .map(|i| {
            let (t, sigma) = (s[i], SMOOTH_SIGMA * radii[i]);
            let half = (3.0 * sigma).min(t).min(length - t);
            if half <= 0.0 || sigma <= 0.0 {
                return values[i];
            }
            let (mut sum, mut weight) = (Vector3::zeros(), 0.0);
            let from = s.partition_point(|&x| x < t - half);
            for (tj, vj) in s[from..].iter().zip(&values[from..]).take_while(|q| *q.0 <= t + half) {
                let w = (-(tj - t).powi(2) / (2.0 * sigma * sigma)).exp();
                sum += vj * w;
                weight += w;
            }
            sum / weight
        })
        .collect()
}
