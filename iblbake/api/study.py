"""The accuracy study: what each approximation of a scene's lighting costs against the reference."""

from __future__ import annotations

from dataclasses import dataclass, field

from iblbake.api.guards import (_arguments, _cache, _callback, _count, _device, _flag, _is_path, _kind, _name,
                                _names, _no_nul, _overrides, _real, _shown, _whole)
from iblbake.api.runtimes import _on_device, _runtime
from iblbake.api.scenes import load_scene
from iblbake.errors import InputError


@dataclass
class Accuracy:
    """What each approximation of a scene's lighting costs and how far it is from the converged
    reference (docs/manual.md 'What accuracy costs').

    records: one dict a rung (the table's rows): term, label, values (the scene keys it sets),
        mode, time_s (median lighting-pass seconds), frame_s, bake_s, kernel_build_s,
        relative_rmse, mean and max relative error, flip (HDR-FLIP, where measured), pareto.
    frontier: term -> the labels on its Pareto frontier of (time, relative RMSE), by time.
    reference: term -> the reference's noise (two seeds; noise_bulk the same over the 99% of
        pixels where they agree best), samples per pixel, what stopped it, seconds; hdr and mask
        are the float32 (H, W, 4) frame and its measured pixels.
    configured: the scene as configured (both terms) against the sum of the references.
    summary: the JSON document `iblbake accuracy --json` prints (accuracy.json).
    study: the study (its scene, settings and each rung's frame, for plots and error maps).
    rungs: the rungs run, in the records' order.
    """

    records: list
    frontier: dict
    reference: dict
    configured: dict
    summary: dict
    study: object = field(repr=False, default=None)
    rungs: list = field(repr=False, default_factory=list)


@_arguments
def accuracy(scene, ladder=None, *, overrides=(), max_side: int = 320, repeats: int = 3,
             target_noise: float = 0.003, max_samples: int = 4096, visibility: bool = True, bounces=None,
             flip: bool = True, cache=None, device: str | None = None, jobs: int = 1, devices=None, warn=None,
             progress=None, before_run=None, names: dict | None = None) -> Accuracy:
    """Render a scene's converged reference per lighting term (diffuse, specular: visibility and
    every bounce, two seeds, its noise measured), then a ladder of approximations of each term,
    each timed (median of `repeats` renders) and measured over the object pixels.

    scene: a scene file, a mapping or a Scene, as load_scene takes (the study loads it at
        `max_side` with each rung's values); overrides: as load_scene's.
    ladder: None (the default ladder for the scene and device), 'realtime' (the real-time modes
        as shipped), 'bases', 'probe_bases', 'lightmaps' or a ladder file ({rungs: [AXIS, ...]} in the sweep
        syntax).
    max_side: 8 to 8192. repeats: 1 to 100.
    bounces: the reference's bounces: 'unbounded' or a count (1: the direct light alone). None is
        unbounded; a value given, other than 1, is warned about where no light passes between
        the scene's surfaces (the reference is then the direct light).
    target_noise (>= 0), max_samples (1 to 2^20): the reference's stopping rule per seed.
    jobs, devices: render the reference seeds in `jobs` worker processes, one device spec each
        in turn (a list), into the cache.
    warn(message): what the study says (a reference stopped short, rungs left out), each message
        once per rung.
    progress(): called as each reference seed and rung is done.
    before_run(study, rungs, reads): called once every rung's scene has validated and before
        anything renders; reads are (what, path) of every file the study reads.
    names: what messages call each argument (by default its name; the command line passes its
        flags).
    """
    import os

    from iblbake.render import Bakes
    from iblbake.scene import load as scene_load
    from iblbake.scene.schema import MAX_BOUNCES
    from iblbake.study import accuracy as acc, ladder as ladders

    # every argument is checked before the scene loads and anything renders
    _names(names)
    if not (ladder is None or _is_path(ladder)):
        raise InputError(f"ladder: give None, one of {', '.join(ladders.LADDERS)} or a ladder file's path, "
                         f"not {_kind(ladder)}")
    if ladder is not None:
        _no_nul("ladder", ladder)
    overrides = _overrides(overrides)
    max_side, repeats = _count("max_side", max_side, 8, 8192), _count("repeats", repeats, 1, 100)
    target_noise = _real("target_noise", target_noise, 0)
    max_samples = _count("max_samples", max_samples, 1, 1 << 20)
    visibility, flip = _flag("visibility", visibility), _flag("flip", flip)
    if not (bounces is None or bounces == "unbounded" or (_whole(bounces) and 1 <= bounces <= MAX_BOUNCES)):
        raise InputError(f"bounces {_shown(bounces)}: use None or 'unbounded', or a count from 1 to {MAX_BOUNCES}")
    bounces = int(bounces) if _whole(bounces) else bounces
    cache = _cache(cache)
    _device(device)
    jobs = _count("jobs", jobs)
    if not (devices is None or (isinstance(devices, (list, tuple)) and all(isinstance(d, str) for d in devices))):
        raise InputError(f"devices: give a list of OpenCL device specs (one a worker, in turn), or None, "
                         f"not {_shown(devices)}")
    for name, f in (("warn", warn), ("progress", progress), ("before_run", before_run)):
        _callback(name, f)
    said = {k: _name(names, k) for k in ("bounces", "max_samples", "max_side", "overrides", "ladder")}
    no_visibility = _name(names, "visibility", "visibility False")

    say = warn or (lambda _m: None)
    given = bounces is not None
    bounces = "unbounded" if bounces is None else bounces
    settings = acc.Settings(max_side=max_side, repeats=repeats, target_noise=target_noise, max_samples=max_samples,
                            flip=flip, visibility=visibility, bounces=bounces)
    # a file is loaded by the study itself (each rung's values over the file's); a mapping or a
    # Scene is validated here with the overrides, and the study validates it again with each
    # rung's values. The overrides are checked here either way, said as this function names them.
    sc = load_scene(scene, overrides, names=names)
    from_file = _is_path(scene)
    rt = _runtime(device, names)
    with _on_device(rt):             # the study's frames on the runtime, one thread at a time
        study = acc.Study(str(scene) if from_file else sc, overrides if from_file else (), settings, runtime=rt,
                          bakes=Bakes(cache), warn=warn, names={k: said[k] for k in ("max_side", "overrides")})
        if given and bounces != 1 and not study.paths:
            why = (f"with {no_visibility} every object is lit as if alone, so no light passes between them"
                   if not visibility else "no light passes between this scene's surfaces")
            say(f"{said['bounces']} {bounces}: {why}; the reference is the direct light (bounces 1)")
        ladder_file = None
        if ladder in ladders.LADDERS:
            rungs = ladders.LADDERS[ladder](study.scene, study.fx)
        elif ladder:
            ladder_file = os.fspath(ladder)
            rungs = ladders.ladder_from_file(ladder_file, study.scene, study.fx, flag=said["ladder"])
        else:
            rungs = ladders.default_ladder(study.scene, study.fx, rt.info.kind, paths=study.paths)
            over = [r for r in rungs if dict(r.values).get("effects.reference.max_samples", 0) > max_samples]
            if over:                     # measured against a reference of fewer samples: their error is its noise
                say(f"left out {len(over)} rungs with more samples than the reference's {said['max_samples']} "
                    f"{max_samples}: {', '.join(r.label for r in over)}")
                rungs = [r for r in rungs if r not in over]
        rungs = [ladders.configured_rung(study.scene, t) for t in study.terms] + rungs
        reads = scene_load.named_input_files(study.scene) + ([("the ladder", ladder_file)] if ladder_file else [])
        atlases = {}                     # lightmap densities: their bakes' size cap, checked up front too
        for r in rungs:                  # every rung's scene validates before anything renders
            rs = study.load(study.rung_values(r), origin=f"ladder rung {r.label!r}")
            reads += scene_load.named_input_files(rs)
            if rs.data["effects"]["diffuse"] == "lightmap":
                atlases.setdefault(rs.data["lightmap"]["texels_per_unit"],
                                   f"ladder rung {r.label!r}: lightmap.texels_per_unit")
        if atlases:
            from iblbake.render.lightmaps.bake import check_sizes
            check_sizes(study.scene, atlases)
        if not os.path.isfile(sc.source):    # a mapping: no scene file is read
            reads = [(what, path) for what, path in reads if what != "the scene file"]
        if before_run:
            before_run(study, rungs, reads)
        spread = None
        if jobs > 1:
            from iblbake.study import workers
            spread = workers.render_references_parallel(study, jobs, list(devices or [device]), warn=say)
        study.progress = progress or (lambda *_: None)
        refs = {t: study.render_reference(t) for t in study.terms}
        rows = [study.run_rung(r) for r in rungs]
        for t in study.terms:
            r = refs[t]
            if "max_samples" in r["stopped"] and r["noise_each"] > 2 * target_noise:
                say(f"the {t} reference stopped at {max_samples} samples per pixel with noise "
                    f"{100 * r['noise']:.2f}% (target {100 * target_noise:g}% per seed): errors below about twice "
                    f"that are its noise. Slow convergence on a path-traced reference is light reaching a "
                    f"surface by a mirror or a glossy lobe from a small bright source (a caustic), which "
                    f"only BSDF sampling finds: raise {said['max_samples']}, or {said['bounces']} 1 for the "
                    f"direct light")
        configured = study.configured_frame()
        front = acc.frontiers(rows)
        high = acc.above_reference(rows)
        if high:
            say(f"{len(high)} {'rungs have' if len(high) > 1 else 'rung has'} more samples than the reference reached "
                f"({', '.join(r['label'] for r in high)}): their error is the reference's noise; kept off "
                f"the frontier (raise {said['max_samples']} above theirs to measure them)")
        records = [{**r, "pareto": r["label"] in front.get(r["term"], [])} for r in rows]
        summary = {
            "scene": str(scene) if from_file else sc.source, "device": rt.device_label,
            "resolution": acc.study_resolution(study.scene, max_side), "repeats": repeats,
            "reference": {t: {k: v for k, v in refs[t].items() if k not in ("hdr", "mask")} | {
                "stopping_rule": f"each seed: relative standard error <= {target_noise} or {max_samples} samples",
                "bounces": bounces if study.paths else 1,
                "object_pixels": int(refs[t]["mask"].sum()),
                "measured_pixels": int(study.metric_mask(t, refs[t]["hdr"]).sum())} for t in study.terms},
            "rungs": records, "frontier": front, "configured": configured,
            "time_split_s": {k: round(v, 3) for k, v in study.times.items()},
        }
        if spread:
            summary["reference_workers"] = spread
        return Accuracy(records, front, refs, configured, summary, study, rungs)
