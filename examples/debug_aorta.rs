use indexmap::IndexMap;
use nalgebra::{Matrix3, Point3, Vector3};
use vesselhex::config::{MeshConfig, Preset};
use vesselhex::input::{read_surface, CenterlinePolyline, Centerlines};
use vesselhex::units::LengthUnit;
fn main() {
    let surface = read_surface(std::path::Path::new("../shared/vessels/vmtk_abdominal_aorta_segment/aorta-surface-segment-2.stl"), LengthUnit::Mm).unwrap();
    let index = vesselhex::surface::LumenSurface::new(&surface).unwrap();
    let n = surface.vertices.len() as f64;
    let mean = surface.vertices.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let cov = surface.vertices.iter().fold(Matrix3::zeros(), |a, p| { let d = p.coords - mean; a + d * d.transpose() }) / n;
    let eig = cov.symmetric_eigen();
    let axis: Vector3<f64> = eig.eigenvectors.column(eig.eigenvalues.imax()).into();
    let t: Vec<f64> = surface.vertices.iter().map(|p| (p.coords - mean).dot(&axis)).collect();
    let (lo, hi) = t.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    let step = 2.0;
    let bins = ((hi - lo) / step).ceil() as usize;
    let mut sums = vec![(Vector3::zeros(), 0usize); bins];
    for (p, &x) in surface.vertices.iter().zip(&t) { let b = (((x - lo) / step) as usize).min(bins - 1); sums[b].0 += p.coords; sums[b].1 += 1; }
    let mut points = vec![]; let mut radii = vec![];
    for (sum, count) in sums { if count >= 20 { let c = Point3::from(sum / count as f64); radii.push(index.closest(&c).distance); points.push(c); } }
    let mut csv = String::from("x,y,z,r\n");
    for (p, r) in points.iter().zip(&radii) { csv += &format!("{},{},{},{}\n", p.x, p.y, p.z, r); }
    std::fs::write("out/aorta_derived.csv", csv).unwrap();
    let cl = Centerlines { polylines: vec![CenterlinePolyline { points, radii: Some(radii), normals: None, cell_tags: IndexMap::new() }], source: "d".into() };
    let config = MeshConfig::preset(Preset::Coarse);
    let tree = vesselhex::centerline::CenterlineTree::build(&cl, &config.centerline).unwrap();
    let l = &config.lumen;
    let template = vesselhex::blocks::SectionTemplate::new(l.core_elements, l.core_size, l.ray_reach);
    let spacing = |s: &vesselhex::centerline::CenterlineSample| l.axial_spacing * s.radius;
    let p = vesselhex::projection::project_branch(&tree.branches[0], &template, &index, &spacing, 0.0, 0.0, true).unwrap();
    let layers = config.wall.layers();
    let levels = vesselhex::volume::RadialLevels::new(vesselhex::blocks::graded_levels(4, 1.2), &layers);
    let th = |r: f64| 0.2 * r;
    let mut mesh = vesselhex::volume::build_volume(&p, &template, &levels, &layers, &th, vesselhex::config::WallGrowth::Normal);
    vesselhex::annotate::annotate(&mut mesh);
    let nl = mesh.lumen_range().len();
    println!("stations {} s {}..{}", p.sections.len(), p.s_start, p.s_end);
    for (e, q) in mesh.quality.iter().enumerate() {
        if q.scaled_jacobian < 0.3 {
            let (region, local) = if e < nl { ("lumen", e) } else { ("wall", e - nl) };
            println!("{e} {region} local {local} sj {:.3} interval {} ring {}", q.scaled_jacobian, local / 16 % 200, local % 16);
        }
    }
    for e in [3397usize, 4005, 4613] {
        let c = mesh.corners(e);
        println!("elem {e} q {:?}", mesh.quality[e]);
        for (j, x) in c.iter().enumerate() { println!("  {j}: {:.3} {:.3} {:.3}", x.x, x.y, x.z); }
    }
    for (i, sec) in p.sections.iter().enumerate().skip(19).take(7) {
        let d: Vec<String> = (0..16).map(|k| format!("{:.1}", (sec.surface[k] - sec.origins[k]).norm())).collect();
        println!("{i} s={:.1} r={:.2} {}", sec.station.s, sec.station.radius, d.join(" "));
    }
}
#[allow(dead_code)]
fn unused() {}
