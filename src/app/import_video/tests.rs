//! Tests of the import window's form and its import thread (folder and Zarr store).

use super::*;
use crate::image::Image;
use crate::io::video::encode_grey_clip;

fn clip(dir: &Path, frames: usize) -> PathBuf {
    let imgs: Vec<Image> = (0..frames)
        .map(|k| Image::from_fn(24, 16, |x, y| ((x + k + y) % 9) as f32 / 8.0))
        .collect();
    let p = dir.join("clip.avi");
    encode_grey_clip(&p, &imgs, false, 25).unwrap();
    p
}

#[test]
fn form_names_what_is_missing_or_invalid() {
    let dir = tempfile::tempdir().unwrap();
    let mut f = ImportForm::default();
    assert_eq!(f.request().unwrap_err(), "choose a video clip");
    f.clip = Some(clip(dir.path(), 8));
    assert_eq!(f.request().unwrap_err(), "choose an output folder");
    f.set_out_from_pick(dir.path());
    assert!(f.out.ends_with("clip-scan"), "{}", f.out);
    f.frames_per_group = 6;
    assert!(f.request().unwrap_err().contains("frames_per_group"));
    f.frames_per_group = 7;
    f.meta.pixel_pitch_um = -1.0;
    assert!(f.request().unwrap_err().contains("camera.pixel_pitch_um"));
    f.meta.pixel_pitch_um = 0.39;
    let req = f.request().unwrap();
    assert_eq!(req.layout.stride(), 12);
    assert_eq!(req.meta.group_step_um, None);
    f.out = dir.path().display().to_string();
    assert!(f.request().unwrap_err().contains("new or empty"));
    f.out = dir
        .path()
        .join("no-such")
        .join("scan")
        .display()
        .to_string();
    assert!(f.request().unwrap_err().contains("does not exist"));
    assert!(!dir.path().join("no-such").exists());
}

#[test]
fn a_store_is_asked_for_or_named_and_goes_on_unless_started_over() {
    let dir = tempfile::tempdir().unwrap();
    let mut f = ImportForm {
        clip: Some(clip(dir.path(), 8)),
        frames_per_group: 7,
        ..ImportForm::default()
    };
    f.set_out_from_pick(dir.path());
    assert_eq!(f.request().unwrap().store, None);
    f.out = dir.path().join("side.ZARR").display().to_string();
    let options = f.request().unwrap().store.unwrap();
    assert!(options.resume && !options.force);
    f.store = true;
    f.start_over = true;
    f.set_out_from_pick(dir.path());
    assert!(f.out.ends_with("clip-scan.zarr"), "{}", f.out);
    let options = f.request().unwrap().store.unwrap();
    assert!(!options.resume && options.force);
    assert_eq!(f.kept_groups(), None);
}

/// Starts `form`'s import and waits for its outcome. With `cancel_at`, the import is held
/// in its progress report of that frame until cancel is raised, so that it stops there
/// however fast it decodes.
#[test]
fn the_form_looks_at_the_disk_when_its_files_change_and_import_looks_again() {
    use egui_kittest::kittest::{NodeT, Queryable};
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scan");
    let form = ImportForm {
        clip: Some(clip(dir.path(), 16)),
        out: out.display().to_string(),
        ..ImportForm::default()
    };
    let state = VideoImport {
        form: Some(form),
        ..VideoImport::default()
    };
    let mut h = egui_kittest::Harness::new_ui_state(
        |ui, (state, action): &mut (VideoImport, Option<ImportAction>)| {
            if let Some(a) = import_video_ui(ui, state) {
                *action = Some(a);
            }
        },
        (state, None),
    );
    h.run();
    assert!(!h.get_by_label("Import").accesskit_node().is_disabled());
    // The output fills after the window looked: Import looks again, starts nothing, and the
    // window names the problem.
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    h.get_by_label("Import").click();
    h.run();
    assert_eq!(h.state().1, None);
    h.get_by_label_contains("must be new or empty");
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine"
    );
    // Emptied and renamed: a new output is looked at as soon as it is typed.
    h.state_mut().0.form.as_mut().unwrap().out = dir.path().join("scan2").display().to_string();
    h.run();
    h.get_by_label("Import").click();
    h.run();
    assert!(matches!(h.state().1, Some(ImportAction::Start(_))));
}

fn finish(form: &ImportForm, cancel_at: Option<usize>) -> Result<ImportSummary, String> {
    let reports = Arc::new(AtomicUsize::new(0));
    let (go, wait) = mpsc::channel::<()>();
    let wait = std::sync::Mutex::new(wait);
    let seen = reports.clone();
    let repaint = Box::new(move || {
        // The first report is (0, total); the k-th after it is frame k decoded.
        if Some(seen.fetch_add(1, Ordering::SeqCst)) == cancel_at {
            let _ = wait.lock().map(|w| w.recv());
        }
    });
    let mut run = ImportRun::start(form.request().unwrap(), repaint).unwrap();
    let started = std::time::Instant::now();
    loop {
        if let Some(o) = run.poll() {
            return o;
        }
        if cancel_at.is_some_and(|n| reports.load(Ordering::SeqCst) > n) {
            run.cancel();
            let _ = go.send(());
        }
        assert!(started.elapsed().as_secs() < 120, "import hung");
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
}

#[test]
fn a_stopped_store_import_keeps_its_groups_and_the_next_goes_on_from_them() {
    let dir = tempfile::tempdir().unwrap();
    let clip = clip(dir.path(), 600);
    let folder = ImportForm {
        clip: Some(clip.clone()),
        out: dir.path().join("scan").display().to_string(),
        frames_per_group: 8,
        group_stride_frames: 6,
        // Groups of these 24 px frames overlap only with a short step.
        own_group_step: true,
        group_step_um: 2.0,
        ..ImportForm::default()
    };
    let store = ImportForm {
        out: dir.path().join("scan.zarr").display().to_string(),
        ..folder.clone()
    };
    let e = finish(&store, Some(200)).unwrap_err();
    assert!(e.contains("cancelled") && e.contains("goes on"), "{e}");
    assert!(!e.contains("--resume"), "{e}");
    let kept = store.kept_groups().unwrap();
    assert!((1..99).contains(&kept), "{kept}");
    assert!(e.contains(&format!("the {kept} groups written")), "{e}");
    // The window says so, and what ticking "start over" does.
    {
        use egui_kittest::kittest::Queryable;
        let mut state = VideoImport {
            form: Some(store.clone()),
            ..VideoImport::default()
        };
        let mut h = egui_kittest::Harness::new_ui_state(
            |ui, state: &mut VideoImport| {
                import_video_ui(ui, state);
            },
            state,
        );
        h.run();
        h.get_by_label_contains(&format!("kept {kept} groups: Import goes on"));
        h.get_by_label("start over").click();
        h.run();
        h.get_by_label_contains("they are discarded");
        state = std::mem::take(h.state_mut());
        assert!(state.form.unwrap().start_over);
    }
    let s = finish(&store, None).unwrap();
    assert_eq!((s.resumed_groups, s.groups), (kept, 99));
    assert_eq!(store.kept_groups(), None);
    let f = finish(&folder, None).unwrap();
    let (a, b) = (
        crate::io::Scan::open(&f.out_dir).unwrap(),
        crate::io::Scan::open(&s.out_dir).unwrap(),
    );
    assert_eq!(a.meta, b.meta);
    assert!(b.groups.iter().all(|g| g.zarr.is_some()));
    for (ga, gb) in a.groups.iter().zip(&b.groups) {
        let (fa, fb) = (
            crate::io::load_group(ga).unwrap(),
            crate::io::load_group(gb).unwrap(),
        );
        assert_eq!(fa, fb, "group {}", ga.index);
    }
}

#[test]
fn run_imports_on_its_thread_and_reports_progress() {
    let dir = tempfile::tempdir().unwrap();
    let mut f = ImportForm {
        clip: Some(clip(dir.path(), 16)),
        out: dir.path().join("scan").display().to_string(),
        frames_per_group: 8,
        group_stride_frames: 8,
        ..ImportForm::default()
    };
    f.own_group_step = true;
    f.group_step_um = 2.0;
    let mut run = ImportRun::start(f.request().unwrap(), Box::new(|| {})).unwrap();
    let started = std::time::Instant::now();
    let outcome = loop {
        if let Some(o) = run.poll() {
            break o;
        }
        assert!(started.elapsed().as_secs() < 60, "import hung");
        std::thread::sleep(std::time::Duration::from_millis(5));
    };
    let s = outcome.unwrap();
    assert_eq!(s.groups, 2);
    assert_eq!(run.progress(), (16, 16));
    let scan = crate::io::Scan::open(&s.out_dir).unwrap();
    assert!((scan.meta.motion.group_step_um - 2.0).abs() < 1e-12);
}
