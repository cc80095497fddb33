"""Coverage-guided fuzzing (atheris, libFuzzer's engine for Python) of the cube-map readers:
the KTX2 parser (iblbake/io/ktx2.parse_cube) on mutated files and the cross/strip face
splitter (iblbake/bake/inputs.faces_of) on images of any shape and layout. Each input must be
read or refused with an InputError whose message is one line naming the file; anything else
(another exception, faces of the wrong shape or type, a face texel that is not one of the
image's) is a finding, which atheris reports and saves as crash-<hash> in the working folder.
(Non-finite texels a file holds are read as stored: the texel policies act on them later.)

    IBLBAKE_FUZZ_READER=ktx2|layout python tests/fuzz_readers.py [CORPUS_DIR] -atheris_runs=N

(one reader per run, so each gets its N executions; both when the variable is unset). make
stress runs a million per reader, the tests 20,000.

The seeds are valid files of every format iblbake writes, built at start-up.
"""

import os
import sys
from pathlib import Path

import atheris

with atheris.instrument_imports():
    import numpy as np

    from iblbake.bake import inputs
    from iblbake.errors import InputError
    from iblbake.io import ktx2

NAME = "fuzz.ktx2"


def seeds():
    rng = np.random.default_rng(0)
    faces = (rng.random((6, 4, 4, 3)) * 8).astype(np.float32)
    return [ktx2.cube_bytes([faces, faces[:, ::2, ::2], faces[:, :1, :1]], fmt) for fmt in ktx2.FORMATS]


def check_ktx2(data: bytes):
    try:
        faces = ktx2.parse_cube(data, NAME)
    except InputError as e:
        assert NAME in str(e) and "\n" not in str(e), repr(e)
        return
    assert faces.ndim == 4 and faces.shape[0] == 6 and faces.shape[1] == faces.shape[2] >= 1 and faces.shape[3] == 3
    assert faces.dtype == np.float32


def check_layout(fdp: atheris.FuzzedDataProvider):
    layout = fdp.PickValueInList(["hcross", "vcross", "hstrip", "vstrip"])
    h, w = fdp.ConsumeIntInRange(0, 48), fdp.ConsumeIntInRange(0, 48)
    image = np.arange(h * w * 3, dtype=np.float32).reshape(h, w, 3)
    try:
        faces = inputs.faces_of(image, layout, NAME)
    except InputError as e:
        assert NAME in str(e) and "\n" not in str(e), repr(e)
        return
    s = faces.shape[1]
    assert faces.shape == (6, s, s, 3) and s >= 1 and 6 * s * s * 3 <= image.size
    # every face texel is one of the image's (no texel invented or left uninitialised)
    assert np.isin(faces, image).all()


READER = os.environ.get("IBLBAKE_FUZZ_READER", "both")


def one_input(data: bytes):
    if READER == "layout" or (READER == "both" and data[:1] == b"L"):
        check_layout(atheris.FuzzedDataProvider(data[1:]))
    else:
        check_ktx2(data)


def main(argv):
    corpus = next((a for a in argv[1:] if not a.startswith("-")), None)
    if corpus and not Path(corpus).is_file():      # a folder: the corpus (a file: reproduce it)
        Path(corpus).mkdir(parents=True, exist_ok=True)
        for i, blob in enumerate(seeds() + [b"L" + bytes(range(16))]):
            (Path(corpus) / f"seed-{i}").write_bytes(blob)
    atheris.Setup(argv, one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main(sys.argv)
