//! The picture of a target (issue 14), over real HTTP on both databases: the PNG the server
//! draws shows the test image changed exactly on the silhouettes the evaluator's renderer gives
//! for the object's ground-truth poses and for the estimates the protocol's n_top selects
//! (computed here from the fixture files), in the documented colours; a private submission's
//! picture is its owner's only, and unknown targets, suffixes and protocols answer 404. The
//! gallery's thumbnail (`?crop=object`) is the same picture cut to the object.

use std::path::Path;

use crate::common::{
    Db, TestDb, both_databases, client, fixtures, get_as, reference_datasets, start, upload_with,
    wait_done,
};
use evaluator::Dataset;
use evaluator::math::Pose;
use evaluator::overlay::{ESTIMATE, GROUND_TRUTH, tint};
use evaluator::render::{Model, Renderer};
use serde_json::Value;

/// An 8-bit RGB(A) PNG as (width, height, RGB bytes).
fn decode_png(bytes: &[u8]) -> (u32, u32, Vec<u8>) {
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::normalize_to_color8());
    let mut reader = decoder.read_info().expect("a PNG");
    let mut buf = vec![0; reader.output_buffer_size().expect("size")];
    let info = reader.next_frame(&mut buf).expect("frame");
    let channels = info.color_type.samples();
    let rgb = buf[..info.buffer_size()]
        .chunks_exact(channels)
        .flat_map(|p| [p[0], p[1 % channels], p[2 % channels]])
        .collect();
    (info.width, info.height, rgb)
}

/// The covered pixels of a render of `model` at `pose`, straight from the renderer's window.
fn mask(
    model: &Model,
    pose: &Pose,
    image: &evaluator::dataset::Image,
    size: (u32, u32),
) -> Vec<bool> {
    let window = Renderer::new().render_model(model, pose, &image.camera, size.0, size.1);
    (0..size.1)
        .flat_map(|y| (0..size.0).map(move |x| (x, y)))
        .map(|(x, y)| window.at(x, y) > 0.0)
        .collect()
}

/// Checks that `thumb`, the picture of target (scene 1, image 0, object 3) cut to the object, is
/// `full`'s pixels in the box of the object's ground-truth silhouettes (rendered here) grown by
/// a quarter of its longer side, at least 16 px, within the image.
fn check_thumbnail(full: &[u8], thumb: &[u8]) {
    let dataset = Dataset::load(&fixtures().join("dataset")).expect("fixture");
    let size = dataset.image_size;
    let image = &dataset.scenes[&1].images[&0];
    let model = Model::new(&dataset.objects[&3].mesh);
    let covered: Vec<bool> = image
        .gt
        .iter()
        .filter(|g| g.obj_id == 3)
        .map(|g| mask(&model, &g.pose, image, size))
        .reduce(|a, b| a.iter().zip(&b).map(|(x, y)| *x || *y).collect())
        .expect("instances");
    let (w, h) = size;
    let on: Vec<(u32, u32)> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter(|&(x, y)| covered[(y * w + x) as usize])
        .collect();
    let x0 = on.iter().map(|p| p.0).min().expect("in view");
    let x1 = on.iter().map(|p| p.0).max().expect("in view") + 1;
    let y0 = on.iter().map(|p| p.1).min().expect("in view");
    let y1 = on.iter().map(|p| p.1).max().expect("in view") + 1;
    let margin = ((x1 - x0).max(y1 - y0) / 4).max(16);
    let (x0, y0) = (x0.saturating_sub(margin), y0.saturating_sub(margin));
    let (x1, y1) = ((x1 + margin).min(w), (y1 + margin).min(h));

    let (fw, fh, f) = decode_png(full);
    let (tw, th, t) = decode_png(thumb);
    assert_eq!((fw, fh), size);
    assert_eq!((tw, th), (x1 - x0, y1 - y0), "the box around the object");
    assert!(tw * th < fw * fh / 4, "{tw} x {th} of {fw} x {fh}");
    for y in 0..th {
        for x in 0..tw {
            let ti = 3 * (y * tw + x) as usize;
            let fi = 3 * ((y0 + y) * fw + x0 + x) as usize;
            assert_eq!(
                t[ti..ti + 3],
                f[fi..fi + 3],
                "pixel {x},{y} of the thumbnail"
            );
        }
    }
}

/// Checks the picture of target (scene 1, image 0, object 3) of `results` against the renderer's
/// masks of its ground truth and of its `keep` best-scored estimates.
fn check_picture(png: &[u8], results: &Path, keep: usize) {
    let dataset = Dataset::load(&fixtures().join("dataset")).expect("fixture");
    let size = dataset.image_size;
    let image = &dataset.scenes[&1].images[&0];
    let model = Model::new(&dataset.objects[&3].mesh);
    let gt: Vec<Vec<bool>> = image
        .gt
        .iter()
        .filter(|g| g.obj_id == 3)
        .map(|g| mask(&model, &g.pose, image, size))
        .collect();
    assert_eq!(gt.len(), 2, "two instances of object 3");
    let parsed = evaluator::results::load_results(results).expect("results");
    let mut mine: Vec<&evaluator::results::Estimate> = parsed
        .estimates
        .iter()
        .filter(|e| (e.scene_id, e.im_id, e.obj_id) == (1, 0, 3))
        .collect();
    assert!(mine.len() > keep, "more estimates than are drawn");
    // Highest score first, ties in file order (a stable sort).
    mine.sort_by(|a, b| b.score.total_cmp(&a.score));
    let est: Vec<Vec<bool>> = mine[..keep]
        .iter()
        .map(|e| mask(&model, &e.pose, image, size))
        .collect();

    let (w, h, drawn) = decode_png(png);
    assert_eq!((w, h), size);
    let photo = std::fs::read(fixtures().join("dataset/test/000001/rgb/000000.png")).expect("rgb");
    let (_, _, photo) = decode_png(&photo);
    let (mut in_gt, mut in_est) = (0, 0);
    for i in 0..(w * h) as usize {
        let orig = [photo[3 * i], photo[3 * i + 1], photo[3 * i + 2]];
        let got = [drawn[3 * i], drawn[3 * i + 1], drawn[3 * i + 2]];
        let g = gt.iter().any(|m| m[i]);
        let e = est.iter().any(|m| m[i]);
        in_gt += usize::from(g);
        in_est += usize::from(e);
        let allowed: Vec<[u8; 3]> = match (g, e) {
            (false, false) => vec![orig],
            (true, false) => vec![tint(orig, GROUND_TRUTH), GROUND_TRUTH],
            (false, true) => vec![tint(orig, ESTIMATE), ESTIMATE],
            (true, true) => vec![
                tint(tint(orig, GROUND_TRUTH), ESTIMATE),
                GROUND_TRUTH,
                ESTIMATE,
            ],
        };
        assert!(
            allowed.contains(&got),
            "pixel ({}, {}): ground truth {g}, estimate {e}: {got:?} is none of {allowed:?}",
            i % w as usize,
            i / w as usize
        );
    }
    assert!(
        in_gt > 100 && in_est > 100,
        "silhouettes {in_gt} and {in_est} pixels"
    );
}

fn target_png(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let db = TestDb::new(kind, "target_png");
    let datasets = reference_datasets(dir.path());
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let file = fixtures().join("results/multi_synthA-test.csv");
    let r = upload_with(
        &server,
        &server.token,
        &[
            ("method", "pictured"),
            ("dataset", "synthA"),
            ("visibility", "private"),
        ],
        &file,
    );
    assert_eq!(r.status(), 202);
    let id = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    let url = |tail: &str| format!("{}/api/v1/submissions/{id}/targets/{tail}", server.base);

    // BOP'19 draws as many estimates as the target has instances (2), ECCV'18 only the best.
    for (protocol, keep) in [("bop19", 2), ("eccv18", 1)] {
        let r = get_as(
            &url(&format!("1/0/3.png?protocol={protocol}")),
            &server.token,
        );
        assert_eq!(r.status(), 200, "{protocol}");
        assert_eq!(r.headers()["content-type"], "image/png");
        check_picture(&r.bytes().expect("png"), &file, keep);
    }

    // The gallery's thumbnail: the same picture cut to the object.
    let full = get_as(&url("1/0/3.png"), &server.token)
        .bytes()
        .expect("png");
    let r = get_as(&url("1/0/3.png?crop=object"), &server.token);
    assert_eq!(r.status(), 200);
    check_thumbnail(&full, &r.bytes().expect("png"));
    let r = get_as(&url("1/0/3.png?crop=scene"), &server.token);
    assert_eq!(r.status(), 400);
    assert!(r.text().expect("text").contains("`object`"));

    // Private: nobody else sees it, not even that it exists.
    let anonymous = client().get(url("1/0/3.png")).send().expect("answered");
    assert_eq!(anonymous.status(), 404);
    for tail in [
        "1/0/99.png",
        "9/0/3.png",
        "1/77/3.png",
        "1/0/3.jpg",
        "1/0/3",
        "1/0/3.png?protocol=bop99",
    ] {
        assert_eq!(get_as(&url(tail), &server.token).status(), 404, "{tail}");
    }
    let missing = format!(
        "{}/api/v1/submissions/999999/targets/1/0/3.png",
        server.base
    );
    assert_eq!(get_as(&missing, &server.token).status(), 404);

    // Submitted for one protocol only: the other has no picture.
    let r = upload_with(
        &server,
        &server.token,
        &[
            ("method", "pictured"),
            ("dataset", "synthA"),
            ("visibility", "public"),
            ("protocol", "bop19"),
        ],
        &fixtures().join("results/noisesmall_synthA-test.csv"),
    );
    assert_eq!(r.status(), 202);
    let public = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    let public_url = |q: &str| {
        format!(
            "{}/api/v1/submissions/{public}/targets/1/0/3.png{q}",
            server.base
        )
    };
    assert_eq!(
        client()
            .get(public_url(""))
            .send()
            .expect("answered")
            .status(),
        200
    );
    // The targets page's gallery shows the thumbnails cut to the object.
    wait_done(&server.base, public, std::time::Duration::from_secs(120));
    let page = client()
        .get(format!("{}/submissions/{public}/targets", server.base))
        .send()
        .expect("answered")
        .text()
        .expect("html");
    assert!(page.contains(".png?crop=object\""), "{page}");
    assert_eq!(
        client()
            .get(public_url("?protocol=eccv18"))
            .send()
            .expect("answered")
            .status(),
        404
    );
}
both_databases!(target_png);
