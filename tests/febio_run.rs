//! FEBio 4.11 runs the decks vesselhex writes, and what it computes shows the physics the decks
//! describe: the wall of a straight tube inflates under the lumen pressure, every lumen node moving
//! away from the axis, by what the CalculiX deck of the same wall and material gives; the hex20
//! wall agrees with the hex8 one; the wall of the Y bifurcation opens without ballooning; the
//! fluid-FSI deck of the Y takes in the prescribed inflow, sends it out of every outlet and moves
//! the wall. Broken copies of a good deck fail these checks.
//!
//! FEBio is the build in `../shared/tools/febio` (its README says how it was made and what it
//! needs: Debian `libumfpack5`), or the folder `$VESSELHEX_FEBIO` names (holding `bin/febio4` and
//! `lib/libfebio_umfpack.so`). Without a working FEBio the tests print "skipped", unless `CI=true`,
//! where they fail.
//!
//! Results are read from FEBio's log: the decks' own `<logfile>` request (the displacements of the
//! interface nodes) and, for the FSI deck, requests added to the copy that runs (the fluid's
//! velocity on the end faces, the wall's on the interface). FEBio numbers the rows of its log by a node's position in
//! `<Nodes>` (1, 2, ...), not by its id: the wall deck writes only the wall's nodes, so there the
//! two differ, and the rows are mapped back to ids through the deck's node order.

mod common;

use common::{ccx_available, frd_displacements, inner_radial, solve_calculix, Displacements};
use nalgebra::{Point3, Vector3};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};
use vesselhex::config::{MeshConfig, Preset};
use vesselhex::mesh::{face_nodes, quad_area_vector, sets, VesselMesh};
use vesselhex::writers::febio::{wall_deck, write_fsi, write_wall, FebioElement, FSI_DECK, WALL_DECK};
use vesselhex::writers::WriteOptions;

// ------------------------------------------------------------------------------------------------
// Running FEBio
// ------------------------------------------------------------------------------------------------

/// The FEBio folder when FEBio works; None (with a "skipped" line) outside CI when it is missing
/// or does not work; a failure under CI.
fn febio_dir() -> Option<&'static Path> {
    static FOUND: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    match FOUND.get_or_init(probe_febio) {
        Ok(dir) => Some(dir),
        Err(why) => {
            assert!(!common::under_ci(), "CI=true but {why}");
            eprintln!("skipped: {why}");
            None
        }
    }
}

/// The FEBio folder if `bin/febio4` starts and loads the UMFPACK plugin (asked to read a deck that
/// does not exist, febio4 loads its plugins and stops).
fn probe_febio() -> Result<PathBuf, String> {
    let dir = std::env::var_os("VESSELHEX_FEBIO")
        .map(PathBuf::from)
        .unwrap_or_else(|| common::crate_dir().join("../shared/tools/febio"));
    let bin = dir.join("bin/febio4");
    if !bin.is_file() {
        return Err(format!(
            "FEBio not found: no {} (set VESSELHEX_FEBIO to the folder holding bin/febio4)",
            bin.display()
        ));
    }
    let missing = std::env::temp_dir().join(format!("vesselhex-no-deck-{}.feb", std::process::id()));
    let out = Command::new(&bin)
        .args(febio_args(&dir, &missing))
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("FEBio {} does not start: {e}", bin.display()))?;
    let said = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    if !said.contains("Success loading plugin") {
        return Err(format!(
            "FEBio {} does not load its UMFPACK plugin (is libumfpack5 installed?):\n{said}",
            bin.display()
        ));
    }
    Ok(dir)
}

/// febio4's arguments for `deck`: no splash, no configuration file, the UMFPACK plugin (FEBio's
/// default linear solver once loaded; the fluid-FSI matrix is non-symmetric, skyline's is not).
fn febio_args(febio: &Path, deck: &Path) -> Vec<String> {
    let plugin = febio.join("lib/libfebio_umfpack.so");
    ["-i", deck.to_str().unwrap(), "-nosplash", "-noconfig", "-import", plugin.to_str().unwrap()]
        .map(String::from)
        .to_vec()
}

/// One FEBio run of a deck: the deck's text and FEBio's log. Its scratch folder is removed when
/// the run is dropped, unless a check failed.
struct FebioRun {
    name: String,
    scratch: PathBuf,
    deck: String,
    log: String,
    /// febio4's exit status was success.
    exit_ok: bool,
    /// How the run ended: its exit code, or stopped at [`RUN_LIMIT`].
    ended: String,
}

impl Drop for FebioRun {
    fn drop(&mut self) {
        if std::thread::panicking() {
            eprintln!("kept for a look: {}", self.scratch.display());
        } else {
            let _ = std::fs::remove_dir_all(&self.scratch);
        }
    }
}

const NORMAL_TERMINATION: &str = " N O R M A L   T E R M I N A T I O N";

/// How long one run may take before it is stopped and counted as failed. The runs here take at
/// most 20 s, but a broken deck can keep FEBio cutting its time step back for a quarter of an hour
/// before it gives up (the Y's wall with its lumen facets wound inwards: 913 s).
const RUN_LIMIT: Duration = Duration::from_secs(300);

/// Runs FEBio (one thread) on `deck` (a path under `scratch`; what FEBio prints goes to a file
/// beside it) and reads its log; checks nothing.
fn run_febio(febio: &Path, name: &str, scratch: &Path, deck: &Path) -> FebioRun {
    let started = Instant::now();
    let console = std::fs::File::create(deck.with_extension("console.txt")).unwrap();
    let mut child = Command::new(febio.join("bin/febio4"))
        .args(febio_args(febio, deck))
        .current_dir(deck.parent().unwrap())
        .env("OMP_NUM_THREADS", "1")
        .stdin(Stdio::null())
        .stdout(console.try_clone().unwrap())
        .stderr(console)
        .spawn()
        .unwrap();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break Some(status);
        }
        if started.elapsed() > RUN_LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let log = std::fs::read_to_string(deck.with_extension("log")).unwrap_or_default();
    let summary: Vec<&str> = log
        .lines()
        .filter(|l| {
            l.contains("Nr of equations")
                || l.contains("time steps completed")
                || l.contains("Total number of equilibrium iterations")
                || l.contains("T E R M I N A T I O N")
        })
        .map(str::trim)
        .collect();
    let ended = match status {
        Some(status) => format!("exit {:?}", status.code()),
        None => format!("stopped after {} s", RUN_LIMIT.as_secs()),
    };
    eprintln!("{name}: febio4 {ended} in {:.1} s; {}", started.elapsed().as_secs_f64(), summary.join("; "));
    FebioRun {
        name: name.into(),
        scratch: scratch.into(),
        deck: std::fs::read_to_string(deck).unwrap(),
        log,
        exit_ok: status.is_some_and(|s| s.success()),
        ended,
    }
}

impl FebioRun {
    /// Normal termination, exit 0, solved with UMFPACK.
    fn assert_normal_termination(&self) {
        let name = &self.name;
        let tail: Vec<&str> = self.log.lines().rev().take(40).collect();
        let tail = tail.into_iter().rev().collect::<Vec<_>>().join("\n");
        let ended = &self.ended;
        assert!(
            self.exit_ok && self.log.contains(NORMAL_TERMINATION),
            "{name}: FEBio did not finish ({ended}):\n{tail}"
        );
        assert!(self.log.contains("Selecting linear solver umfpack"), "{name}: FEBio did not solve with UMFPACK");
    }

    /// The deck's node coordinates by id.
    fn node_points(&self) -> HashMap<u64, Point3<f64>> {
        deck_nodes(&self.deck).into_iter().collect()
    }

    /// The last record of a node-data vector `data` (e.g. `ux;uy;uz`) in the log: its time and its
    /// vectors by node id.
    fn last_node_record(&self, data: &str) -> (f64, HashMap<u64, [f64; 3]>) {
        let ids: Vec<u64> = deck_nodes(&self.deck).into_iter().map(|(id, _)| id).collect();
        let record = last_record(&self.log, data)
            .unwrap_or_else(|| panic!("{}: no record of {data} in the FEBio log", self.name));
        let by_id = record
            .rows
            .into_iter()
            .map(|(position, v)| {
                assert_eq!(v.len(), 3, "{}: a row of {data} with {} values", self.name, v.len());
                (ids[position - 1], [v[0], v[1], v[2]])
            })
            .collect();
        (record.time, by_id)
    }

    /// The interface displacements the decks log, at the end of the run.
    fn displacements(&self) -> (f64, Displacements) {
        self.last_node_record("ux;uy;uz")
    }
}

/// The nodes of a deck, id and point, in the order of `<Nodes>` (FEBio's log numbers its rows by
/// this position).
fn deck_nodes(deck: &str) -> Vec<(u64, Point3<f64>)> {
    deck.lines()
        .filter_map(|l| l.trim_start().strip_prefix("<node id=\""))
        .map(|rest| {
            let (id, rest) = rest.split_once('"').unwrap();
            let xyz = rest.split('>').nth(1).unwrap().split('<').next().unwrap();
            let v: Vec<f64> = xyz.split(',').map(|x| x.parse().unwrap()).collect();
            (id.parse().unwrap(), Point3::new(v[0], v[1], v[2]))
        })
        .collect()
}

/// One data record of a FEBio log: its time and its rows (1-based item, values).
struct Record {
    time: f64,
    rows: Vec<(usize, Vec<f64>)>,
}

/// The last data record named `data` in a FEBio log. A record is `Data Record #k`, a rule,
/// `Step = n`, `Time = t`, `Data = name`, then one row `item,value,value...` per item.
fn last_record(log: &str, data: &str) -> Option<Record> {
    let mut last = None;
    let mut lines = log.lines().peekable();
    while let Some(line) = lines.next() {
        if !line.starts_with("Data Record #") {
            continue;
        }
        let mut time = f64::NAN;
        let mut name = "";
        while let Some(l) = lines.next_if(|l| !l.starts_with("Data =")) {
            if let Some(t) = l.strip_prefix("Time = ") {
                time = t.trim().parse().unwrap();
            }
        }
        if let Some(l) = lines.next() {
            name = l.trim_start_matches("Data =").trim();
        }
        let mut rows = Vec::new();
        while let Some(row) = lines.peek().and_then(|l| parse_row(l)) {
            rows.push(row);
            lines.next();
        }
        if name == data {
            last = Some(Record { time, rows });
        }
    }
    last
}

fn parse_row(line: &str) -> Option<(usize, Vec<f64>)> {
    let mut fields = line.split(',');
    let item = fields.next()?.trim().parse().ok()?;
    let values = fields.map(|f| f.trim().parse().ok()).collect::<Option<Vec<f64>>>()?;
    (!values.is_empty()).then_some((item, values))
}

// ------------------------------------------------------------------------------------------------
// The wall deck
// ------------------------------------------------------------------------------------------------

/// The straight fixture (r = 2 mm, 30 mm along z) at the coarse preset with axial elements of two
/// radii (4 mm: the tube inflates uniformly along its length, the end rings being held only
/// axially), so that its hex20 and CalculiX twins solve in seconds.
fn straight_fixture() -> VesselMesh {
    let (surface, centerline) = common::fixture("straight");
    let mut config = MeshConfig::preset(Preset::Coarse);
    config.lumen.axial_spacing = 2.0;
    common::mesh_files(&surface, &centerline, &config)
}

/// Writes `mesh`'s wall deck into a scratch folder and runs FEBio on it.
fn run_wall_deck(febio: &Path, mesh: &VesselMesh, options: &WriteOptions, name: &str) -> FebioRun {
    let scratch = common::temp_dir(&format!("febio-{name}"));
    write_wall(mesh, options, &scratch).unwrap();
    run_febio(febio, name, &scratch, &scratch.join(WALL_DECK))
}

/// Runs the wall deck to normal termination at the full pressure (t = 1) and returns the
/// displacements of the interface nodes (all of them: FEBio logged one row each).
fn inflate(febio: &Path, mesh: &VesselMesh, options: &WriteOptions, name: &str) -> (FebioRun, Displacements) {
    let run = run_wall_deck(febio, mesh, options, name);
    run.assert_normal_termination();
    let (time, disp) = run.displacements();
    assert!((time - 1.0).abs() < 1e-9, "{name}: the last record is at t = {time}, not at the full pressure");
    for &n in &mesh.node_sets[sets::INTERFACE_NODES] {
        assert!(disp.contains_key(&(n as u64 + 1)), "{name}: FEBio logged no displacement of node {}", n + 1);
    }
    (run, disp)
}

/// The logged nodes of a tube along z that do not move away from its axis, with their radial
/// displacement; every logged node's (corner and, in a hex20 deck, mid-edge) from the deck's
/// coordinates. Also the least radial displacement.
fn tube_nodes_not_moving_out(run: &FebioRun, disp: &Displacements) -> (Vec<(u64, f64)>, f64) {
    let points = run.node_points();
    let mut least = f64::INFINITY;
    let mut inward = Vec::new();
    for (&id, u) in disp {
        let p = points[&id];
        let ur = (u[0] * p.x + u[1] * p.y) / p.x.hypot(p.y);
        least = least.min(ur);
        if ur <= 0.0 {
            inward.push((id, ur));
        }
    }
    inward.sort_by_key(|m| m.0);
    (inward, least)
}

/// The straight fixture's hex8 wall deck run once (the hex8 and hex20 tests both use it).
fn straight_hex8(febio: &Path) -> &'static (VesselMesh, Displacements) {
    static RUN: OnceLock<(VesselMesh, Displacements)> = OnceLock::new();
    RUN.get_or_init(|| {
        let mesh = straight_fixture();
        let (run, disp) = inflate(febio, &mesh, &WriteOptions::default(), "straight-hex8");
        let (inward, least) = tube_nodes_not_moving_out(&run, &disp);
        assert!(inward.is_empty(), "lumen nodes not moving outward (id, u_r mm): {inward:?}");
        eprintln!("straight-hex8: {} lumen nodes, least u_r {least:.5} mm", disp.len());
        (mesh, disp)
    })
}

/// ccx's displacements of the straight fixture's wall (its CalculiX deck: the same mesh and
/// `[material]`), computed once; None when ccx is missing outside CI.
fn straight_ccx(mesh: &VesselMesh) -> Option<&'static Displacements> {
    static RUN: OnceLock<Displacements> = OnceLock::new();
    if !ccx_available() {
        return None;
    }
    Some(RUN.get_or_init(|| frd_displacements(&solve_calculix(mesh, &WriteOptions::default(), "febio-twin").dir)))
}

/// How a FEBio wall of the straight fixture differs from ccx's: the mean inner-radius increases
/// away from the ends (mm), and the lumen node farthest from where ccx puts it and how far (mm).
struct AgainstCcx {
    febio_u: f64,
    ccx_u: f64,
    worst: f64,
    node: u64,
}

impl AgainstCcx {
    fn of(mesh: &VesselMesh, disp: &Displacements, ccx: &Displacements) -> Self {
        let (worst, node) = mesh.node_sets[sets::INTERFACE_NODES]
            .iter()
            .map(|&n| {
                let id = n as u64 + 1;
                ((Vector3::from(disp[&id]) - Vector3::from(ccx[&id])).norm(), id)
            })
            .fold((0.0, 0), |a, b| if b.0 > a.0 { b } else { a });
        AgainstCcx { febio_u: inner_radial(mesh, disp).0, ccx_u: inner_radial(mesh, ccx).0, worst, node }
    }

    /// Where the two walls differ more than two decks of one model may: the mean increases more
    /// than 2 % apart, a lumen node more than 3 % of ccx's mean increase from where ccx puts it.
    fn faults(&self) -> Vec<String> {
        let AgainstCcx { febio_u, ccx_u, worst, node } = *self;
        let mut faults = Vec::new();
        if !(febio_u > 0.0 && (febio_u / ccx_u - 1.0).abs() < 0.02) {
            faults.push(format!("mean inner-radius increase {febio_u} mm, ccx's {ccx_u} mm"));
        }
        if worst >= 0.03 * ccx_u {
            faults.push(format!("lumen node {node} is {worst} mm from where ccx puts it"));
        }
        faults
    }
}

/// The default wall (HGO layers, 100 mmHg) of the straight fixture, hex8: FEBio inflates it,
/// every lumen node moves away from the axis, and as the CalculiX deck of the same mesh and
/// `[material]` does (ccx's C3D8I against FEBio's hex8): the mean inner-radius increase away
/// from the ends within 2 % of ccx's (measured 0.35 %), every lumen node's displacement within
/// 3 % of that mean of ccx's (measured 1.4 %; a deck with one element per layer left without its
/// `mat_axis` moves a lumen node by 8.5 %, [`wall_deck_missing_mat_axes_fails`]).
#[test]
fn straight_wall_inflates_as_the_calculix_deck_does() {
    let Some(febio) = febio_dir() else { return };
    let (mesh, disp) = straight_hex8(febio);
    let Some(ccx) = straight_ccx(mesh) else { return };
    let against = AgainstCcx::of(mesh, disp, ccx);
    let AgainstCcx { febio_u, ccx_u, worst, node } = against;
    eprintln!(
        "straight wall at 100 mmHg: inner radius grows by {febio_u:.5} mm in FEBio, {ccx_u:.5} mm in ccx ({:+.2} %); \
         lumen nodes at most {worst:.2e} mm apart (node {node}, {:.2} % of ccx's mean)",
        100.0 * (febio_u / ccx_u - 1.0),
        100.0 * worst / ccx_u
    );
    let faults = against.faults();
    assert!(faults.is_empty(), "FEBio and ccx differ: {faults:?}");
}

/// The hex20 wall deck (`[febio] element = "hex20"`): FEBio inflates it, every lumen node, corner
/// or mid-edge, moves away from the axis, and the mean inner-radius increase is within 2 % of the
/// hex8 deck's (measured 0.5 %). In 5 steps, not the default 10: FEBio converges in either (the
/// same displacements to 1e-7 mm) and every step factors the hex20 stiffness anew.
#[test]
fn hex20_wall_inflates_as_the_hex8_wall_does() {
    let Some(febio) = febio_dir() else { return };
    let (mesh, hex8) = straight_hex8(febio);
    let mut options = WriteOptions::default();
    options.febio.element = FebioElement::Hex20;
    options.febio.static_steps = 5;
    let (run, disp) = inflate(febio, mesh, &options, "straight-hex20");
    let (inward, least) = tube_nodes_not_moving_out(&run, &disp);
    assert!(disp.len() > hex8.len(), "no mid-edge lumen nodes logged");
    assert!(inward.is_empty(), "hex20 lumen nodes not moving outward (id, u_r mm): {inward:?}");
    let (u20, _, _) = inner_radial(mesh, &disp);
    let (u8, _, _) = inner_radial(mesh, hex8);
    let gap = u20 / u8 - 1.0;
    eprintln!(
        "hex20: {} lumen nodes, least u_r {least:.5} mm; mean inner-radius increase {u20:.5} mm, hex8 {u8:.5} mm \
         ({:+.2} %)",
        disp.len(),
        100.0 * gap
    );
    assert!(gap.abs() < 0.02, "hex20 {u20} mm vs hex8 {u8} mm");
}

/// The bundled Y bifurcation (coarse): its wall deck (inlet ring held axially, the two oblique
/// outlet rings clamped) runs to the full pressure and the lumen opens in every branch without
/// ballooning.
#[test]
fn branched_wall_opens_in_every_branch() {
    let Some(febio) = febio_dir() else { return };
    let mesh = y_bifurcation(&MeshConfig::preset(Preset::Coarse));
    let (_run, disp) = inflate(febio, &mesh, &WriteOptions::default(), "y-wall");
    common::assert_lumen_opens("y-wall (FEBio)", &mesh, &disp);
}

fn y_bifurcation(config: &MeshConfig) -> VesselMesh {
    let dir = common::fixtures_dir();
    common::mesh_files(&dir.join("y_bifurcation.stl"), &dir.join("y_bifurcation_centerlines.vtp"), config)
}

// ------------------------------------------------------------------------------------------------
// The fluid-FSI deck
// ------------------------------------------------------------------------------------------------

/// The FSI run's case file: the Y at the coarse preset made coarser still (8 elements around, 2
/// across the lumen, axial elements of one radius), so that the run takes seconds (5,884
/// equations; the straight fixture at the plain coarse preset has 20,029 and takes 105 s), and
/// five steps of 1 ms over which the inflow ramps up to its full 0.1 m/s. The outlets are held at
/// 0 mmHg: a rising outlet pressure inflates the wall with blood drawn in through the outlets (as
/// in the verified example), which would hide whether the deck sends its inflow out; the wall then
/// moves under the pressure that accelerates the blood.
const FSI_CASE: &str = r#"
preset = "coarse"
[lumen]
core_elements = 2
radial_elements = 2
axial_spacing = 1.0
[febio.fsi]
inlet_mean_velocity_m_s = 0.1
outlet_pressure_mmhg = 0.0
ramp_s = 0.005
step_size_s = 0.001
time_steps = 5
"#;

/// The nodes of the lumen's end faces (inlet and outlets), sorted.
fn end_face_nodes(mesh: &VesselMesh) -> Vec<u32> {
    let mut nodes: Vec<u32> = mesh
        .ends
        .iter()
        .flat_map(|end| &mesh.face_sets[&sets::lumen_end(&end.name)])
        .flat_map(|f| face_nodes(&mesh.hexes[f.element as usize], f.face as usize))
        .collect();
    nodes.sort_unstable();
    nodes.dedup();
    nodes
}

/// The copy of a deck that runs: the deck with more node-data requests in its log, each a
/// variable (e.g. `nfvx;nfvy;nfvz`) and the mesh nodes to log it at.
fn with_log_requests(deck: &str, requests: &[(&str, &[u32])]) -> String {
    let position: HashMap<u64, usize> =
        deck_nodes(deck).into_iter().enumerate().map(|(k, (id, _))| (id, k + 1)).collect();
    let mut added = String::new();
    for (data, nodes) in requests {
        let items: Vec<String> = nodes.iter().map(|&n| position[&(n as u64 + 1)].to_string()).collect();
        added += &format!("<node_data data=\"{data}\" delim=\",\">{}</node_data>\n", items.join(","));
    }
    let (head, tail) = deck.split_once("<logfile>\n").expect("the deck has a <logfile> section");
    format!("{head}<logfile>\n{added}{tail}")
}

/// The volume flow out of an end (along its outward normal) and the end's area: each face's area
/// times the mean of its four nodes' velocities (exact for a bilinear field on a parallelogram).
fn outflow(mesh: &VesselMesh, end: &vesselhex::mesh::VesselEnd, velocity: &HashMap<u64, [f64; 3]>) -> (f64, f64) {
    let (mut flow, mut area) = (0.0, 0.0);
    for f in &mesh.face_sets[&sets::lumen_end(&end.name)] {
        let q = face_nodes(&mesh.hexes[f.element as usize], f.face as usize);
        let a = quad_area_vector(q.map(|n| mesh.nodes[n as usize])).norm();
        let mean: Vector3<f64> =
            q.iter().map(|&n| Vector3::from(velocity[&(n as u64 + 1)])).sum::<Vector3<f64>>() / 4.0;
        flow += a * mean.dot(&end.outward_normal);
        area += a;
    }
    (flow, area)
}

/// The rate at which the lumen grows: the wall's velocity through the lumen's wall faces (out of
/// the lumen), each face's area vector times the mean of its four nodes' velocities.
fn lumen_growth_rate(mesh: &VesselMesh, wall_velocity: &HashMap<u64, [f64; 3]>) -> f64 {
    mesh.face_sets[sets::LUMEN_WALL_FACES]
        .iter()
        .map(|f| {
            let q = face_nodes(&mesh.hexes[f.element as usize], f.face as usize);
            let a = quad_area_vector(q.map(|n| mesh.nodes[n as usize]));
            let mean = q.iter().map(|&n| Vector3::from(wall_velocity[&(n as u64 + 1)])).sum::<Vector3<f64>>() / 4.0;
            a.dot(&mean)
        })
        .sum()
}

/// Meshes the Y with [`FSI_CASE`], writes its FSI deck with two more log requests, the fluid's
/// velocity on the end faces (the deck holds the mesh still there, so the fluid's velocity
/// relative to the mesh is its velocity) and the wall's on the interface, and runs FEBio on it to
/// normal termination.
fn run_fsi_deck_of_the_y(febio: &Path) -> (VesselMesh, WriteOptions, FebioRun) {
    let scratch = common::temp_dir("febio-y-fsi");
    let case = scratch.join("case.toml");
    std::fs::write(&case, FSI_CASE).unwrap();
    let config = MeshConfig::from_case_file(&case, None).unwrap();
    let mesh = y_bifurcation(&config);
    let options = WriteOptions::from_config(&config);
    assert_eq!(options.length_unit, vesselhex::units::LengthUnit::Mm, "the flows below are in mm^3/s");
    write_fsi(&mesh, &options, &scratch).unwrap();
    let deck = scratch.join(FSI_DECK);
    let text = std::fs::read_to_string(&deck).unwrap();
    let requests: [(&str, &[u32]); 2] =
        [("nfvx;nfvy;nfvz", &end_face_nodes(&mesh)), ("vx;vy;vz", &mesh.node_sets[sets::INTERFACE_NODES])];
    std::fs::write(&deck, with_log_requests(&text, &requests)).unwrap();
    let run = run_febio(febio, "y-fsi", &scratch, &deck);
    run.assert_normal_termination();
    (mesh, options, run)
}

/// The fluid-FSI deck of the Y bifurcation, run for five time steps ([`FSI_CASE`]): FEBio ends
/// normally; the inlet takes in the prescribed flow (mean velocity times area, within 5 %); every
/// outlet sends flow out; the wall moves out of the lumen (by more than 1e-4 of the inlet radius
/// on average, measured 2e-3: without the fluid-FSI traction the wall moves by 1e-14 mm, with a
/// wall 1e9 times too heavy by 1e-8 of the right amount, FORMATS.md 2b); and what comes in either
/// leaves or fills the widening lumen: inflow = outflow + the lumen's growth rate (the blood is
/// nearly incompressible), within 10 % of the inflow, what flows computed from nodal velocities
/// on a mesh of 8 elements around leave unbalanced (measured 6 %).
#[test]
fn fsi_deck_sends_the_inflow_out_of_every_outlet_and_moves_the_wall() {
    let Some(febio) = febio_dir() else { return };
    let (mesh, options, run) = run_fsi_deck_of_the_y(febio);
    let f = &options.febio.fsi;
    let end_time = f.time_steps as f64 * f.step_size_s;
    let (time, velocity) = run.last_node_record("nfvx;nfvy;nfvz");
    assert!((time - end_time).abs() < 1e-9, "the last record is at t = {time} s, not {end_time} s");
    let (inlet_out, inlet_area) = outflow(&mesh, mesh.inlet().unwrap(), &velocity);
    let inflow = -inlet_out;
    let prescribed = 1e3 * f.inlet_mean_velocity_m_s * (end_time / f.ramp_s).min(1.0) * inlet_area;
    let outlets: Vec<(String, f64)> =
        mesh.outlets().map(|end| (end.name.clone(), outflow(&mesh, end, &velocity).0)).collect();
    let out_total: f64 = outlets.iter().map(|o| o.1).sum();
    let growth = lumen_growth_rate(&mesh, &run.last_node_record("vx;vy;vz").1);
    let (_, disp) = run.displacements();
    let motion = common::lumen_normal_motion(&mesh, &disp);
    let mean_un = motion.iter().map(|m| m.1).sum::<f64>() / motion.len() as f64;
    let inward = motion.iter().filter(|m| m.1 <= 0.0).count();
    eprintln!(
        "y-fsi at t = {time} s: inflow {inflow:.2} mm^3/s (prescribed {prescribed:.2}); outflow {out_total:.2} \
         ({outlets:?}); lumen growth {growth:.2} mm^3/s; wall: mean u.n {mean_un:.3e} mm over {} lumen nodes, {inward} \
         moving inwards",
        motion.len()
    );
    assert!((inflow / prescribed - 1.0).abs() < 0.05, "inflow {inflow} mm^3/s, prescribed {prescribed}");
    for (name, q) in &outlets {
        assert!(*q > 0.0, "no flow out of {name}: {q} mm^3/s");
    }
    let inlet_radius = (inlet_area / std::f64::consts::PI).sqrt();
    assert!(mean_un > 1e-4 * inlet_radius, "the wall does not move out of the lumen: mean u.n {mean_un} mm");
    let unbalanced = inflow - out_total - growth;
    assert!(unbalanced.abs() < 0.1 * inflow, "inflow {inflow} - outflow {out_total} - growth {growth} mm^3/s");
}

// ------------------------------------------------------------------------------------------------
// Broken decks
// ------------------------------------------------------------------------------------------------

/// `deck` with the facets of surface `name` wound the other way (each facet's corners reversed).
fn with_reversed_facets(deck: &str, name: &str) -> String {
    let open = format!("<Surface name=\"{name}\">");
    let (mut inside, mut reversed) = (false, 0);
    let mut out = String::new();
    for line in deck.lines() {
        inside = (inside || line.trim() == open) && line.trim() != "</Surface>";
        match line.trim().strip_prefix("<quad4 ").filter(|_| inside) {
            Some(rest) => {
                let (id, corners) = rest.split_once('>').unwrap();
                let mut corners: Vec<&str> = corners.trim_end_matches("</quad4>").split(',').collect();
                corners.reverse();
                out += &format!("<quad4 {id}>{}</quad4>\n", corners.join(","));
                reversed += 1;
            }
            None => out += &format!("{line}\n"),
        }
    }
    assert!(reversed > 0, "no facets of {name} reversed");
    out
}

/// `deck` with its first element turned inside out (its two ends swapped).
fn with_first_element_inverted(deck: &str) -> String {
    let start = deck.find("<elem id=\"").unwrap();
    let end = start + deck[start..].find("</elem>").unwrap();
    let (open, corners) = deck[start..end].split_once('>').unwrap();
    let corners: Vec<&str> = corners.split(',').collect();
    assert_eq!(corners.len(), 8);
    let swapped = [&corners[4..], &corners[..4]].concat().join(",");
    format!("{}{open}>{swapped}{}", &deck[..start], &deck[end..])
}

/// Runs FEBio on `text`, a deck written into a scratch folder of its own.
fn run_deck_text(febio: &Path, name: &str, text: &str) -> FebioRun {
    let scratch = common::temp_dir(&format!("febio-{name}"));
    std::fs::write(scratch.join("wall.feb"), text).unwrap();
    run_febio(febio, name, &scratch, &scratch.join("wall.feb"))
}

/// The straight fixture's wall deck with its lumen facets wound the wrong way: the pressure pulls
/// the wall in, and though FEBio ends normally, lumen nodes move towards the axis, which the good
/// deck's check catches. (10 mmHg in 2 steps, so that the wall pulled in does not buckle.)
#[test]
fn wall_deck_with_inward_facets_fails() {
    let Some(febio) = febio_dir() else { return };
    let (mesh, _) = straight_hex8(febio);
    let mut options = WriteOptions::default();
    options.febio.lumen_pressure_mmhg = 10.0;
    options.febio.static_steps = 2;
    let deck = with_reversed_facets(&wall_deck(mesh, &options).unwrap(), sets::WALL_LUMEN_FACES);
    let run = run_deck_text(febio, "inward-facets", &deck);
    run.assert_normal_termination();
    let disp = run.displacements().1;
    let (inward, _) = tube_nodes_not_moving_out(&run, &disp);
    eprintln!("inward-facets: {} of {} lumen nodes move inwards", inward.len(), disp.len());
    assert!(!inward.is_empty(), "every lumen node still moves outward");
}

/// The straight fixture's wall deck with an element turned inside out: FEBio stops (a negative
/// Jacobian, exit code 1).
#[test]
fn wall_deck_with_an_inverted_element_fails() {
    let Some(febio) = febio_dir() else { return };
    let (mesh, _) = straight_hex8(febio);
    let deck = with_first_element_inverted(&wall_deck(mesh, &WriteOptions::default()).unwrap());
    let run = run_deck_text(febio, "inverted-element", &deck);
    assert!(!run.exit_ok && !run.log.contains(NORMAL_TERMINATION), "FEBio ran the deck");
    assert!(run.log.to_lowercase().contains("negative jacobian"), "FEBio stopped for another reason");
}

/// The straight fixture's wall deck with one element per layer left out of the `mat_axis` maps
/// (FEBio puts it on the global axes, FORMATS.md 2b): FEBio ends normally and every lumen node
/// still moves outward, but the wall no longer inflates as the CalculiX deck's does.
#[test]
fn wall_deck_missing_mat_axes_fails() {
    let Some(febio) = febio_dir() else { return };
    let (mesh, _) = straight_hex8(febio);
    let Some(ccx) = straight_ccx(mesh) else { return };
    let deck = without_middle_mat_axes(&wall_deck(mesh, &WriteOptions::default()).unwrap());
    let run = run_deck_text(febio, "missing-mat-axes", &deck);
    run.assert_normal_termination();
    let faults = AgainstCcx::of(mesh, &run.displacements().1, ccx).faults();
    eprintln!("missing-mat-axes: {faults:?}");
    assert!(!faults.is_empty(), "the wall still inflates as ccx's does");
}

/// `deck` without the middle entry of each `mat_axis` map.
fn without_middle_mat_axes(deck: &str) -> String {
    let mut out = String::new();
    let mut block: Vec<&str> = Vec::new();
    for line in deck.lines() {
        if line.trim_start().starts_with("<elem lid=") {
            block.push(line);
            continue;
        }
        if !block.is_empty() {
            let middle = block.len() / 2;
            for (k, entry) in block.drain(..).enumerate() {
                if k != middle {
                    out += &format!("{entry}\n");
                }
            }
        }
        out += &format!("{line}\n");
    }
    assert!(out.len() < deck.len(), "no mat_axis entry removed");
    out
}
