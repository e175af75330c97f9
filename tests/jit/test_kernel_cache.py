"""numba's cache of the kernels is emptied when any source of the folder changes
(core/jit/kernel_cache.py): numba itself only checks each function's own file."""

from drake_tracker.core.jit.kernel_cache import clear_stale_kernel_cache, sources_hash


def test_a_changed_source_empties_the_folder_cache(tmp_path):
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "b.py").write_text("y = 2\n")
    cache = tmp_path / "__pycache__"
    cache.mkdir()
    (cache / "a.f-1.py311.nbi").write_bytes(b"index")
    (cache / "a.f-1.py311.1.nbc").write_bytes(b"code")
    (cache / "a.cpython-311.pyc").write_bytes(b"bytecode")
    assert clear_stale_kernel_cache(tmp_path)  # no stamp yet: cleared
    assert sorted(p.name for p in cache.iterdir()) == ["a.cpython-311.pyc",
                                                       "kernel_sources.sha256"]
    (cache / "a.f-1.py311.nbi").write_bytes(b"index")
    assert not clear_stale_kernel_cache(tmp_path)  # unchanged sources: kept
    assert (cache / "a.f-1.py311.nbi").exists()
    before = sources_hash(tmp_path)
    (tmp_path / "b.py").write_text("y = 3\n")  # a callee's file changes
    assert sources_hash(tmp_path) != before
    assert clear_stale_kernel_cache(tmp_path)
    assert not (cache / "a.f-1.py311.nbi").exists()


def test_callers_caches_are_emptied_with_the_folder_cache(tmp_path):
    """A kernel in another folder that calls this folder's kernels holds their compiled
    code in its own cache entry: it goes too (the bench's replay of the scoring kernel
    measured the previous kernel after a change to core/ before this)."""
    core, caller = tmp_path / "core", tmp_path / "package"
    for folder in (core, caller):
        (folder / "__pycache__").mkdir(parents=True)
    (core / "a.py").write_text("x = 1\n")
    entry = caller / "__pycache__" / "bench.replay-1.py311.1.nbc"
    entry.write_bytes(b"code with a's kernel inlined")
    assert clear_stale_kernel_cache(core, (caller,))
    assert not entry.exists()
    entry.write_bytes(b"code")
    assert not clear_stale_kernel_cache(core, (caller,))  # unchanged: kept
    assert entry.exists()
    (core / "a.py").write_text("x = 2\n")
    assert clear_stale_kernel_cache(core, (caller,))
    assert not entry.exists()


def test_an_unwritable_folder_is_left_alone(tmp_path):
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "__pycache__").write_text("not a folder")  # mkdir / glob fail
    assert clear_stale_kernel_cache(tmp_path) is False
