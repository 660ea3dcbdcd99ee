"""Fixtures of the app tests: a headless EGL context for the window's GL parts."""

import pytest


@pytest.fixture(scope="module")
def gl_ctx():
    """A moderngl context with no display (EGL; Mesa's on CI, the GPU's where present)."""
    import moderngl

    try:
        c = moderngl.create_standalone_context(backend="egl")
    except Exception as exc:   # a missing libEGL is a setup error, not a skip
        pytest.fail(f"no EGL context ({exc}); install Mesa's EGL (libegl1, libgl1-mesa-dri); "
                    ".ci/run does")
    yield c
    c.release()
