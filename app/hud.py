"""The heads-up display: text lines drawn by moderngl over the image.

A glyph atlas of printable ASCII is rasterised once with Pillow's default font into a
single-channel texture; each line becomes one quad per glyph (two triangles, pixel positions and
atlas coordinates) behind which a translucent box is drawn. :func:`hud_lines` and
:func:`help_lines` are pure (stats in, strings out) so they are tested without GL.
"""

from __future__ import annotations

import numpy as np

FIRST, LAST = 32, 126    # printable ASCII in the atlas; others draw as '?'

_VS = """
#version 330
uniform vec2 screen;
in vec2 pos;
in vec2 uv;
in vec4 color;
out vec2 v_uv;
out vec4 v_color;
void main() {
    v_uv = uv;
    v_color = color;
    gl_Position = vec4(2.0 * pos.x / screen.x - 1.0, 1.0 - 2.0 * pos.y / screen.y, 0.0, 1.0);
}
"""
_FS = """
#version 330
uniform sampler2D atlas;
in vec2 v_uv;
in vec4 v_color;
out vec4 frag;
void main() {
    float a = v_uv.x < 0.0 ? 1.0 : texture(atlas, v_uv).r;   // uv.x < 0: a solid box
    frag = vec4(v_color.rgb, v_color.a * a);
}
"""


class GlyphAtlas:
    """Printable ASCII rasterised once: ``image`` (H, W) uint8 coverage, per glyph its atlas
    box (x, y) and advance (px); every glyph cell is ``cell`` = (w, h) px."""

    def __init__(self, size: int = 14):
        from PIL import Image, ImageDraw, ImageFont

        font = ImageFont.load_default(size=size)
        ascent, descent = font.getmetrics()
        chars = [chr(c) for c in range(FIRST, LAST + 1)]
        cw = max(int(np.ceil(font.getbbox(c)[2])) for c in chars) + 1
        ch = ascent + descent + 1
        cols = 16
        rows = -(-len(chars) // cols)
        img = Image.new("L", (cols * cw, rows * ch), 0)
        draw = ImageDraw.Draw(img)
        self.boxes, self.advance = {}, {}
        for k, c in enumerate(chars):
            x, y = (k % cols) * cw, (k // cols) * ch
            draw.text((x, y), c, fill=255, font=font)
            self.boxes[c] = (x, y)
            self.advance[c] = float(font.getlength(c))
        self.image = np.asarray(img, np.uint8)
        self.cell = (cw, ch)
        self.line_height = ch + 2

    def _codes(self, text: str) -> np.ndarray:
        """Character codes of ``text``, with '?' for what the atlas lacks."""
        c = np.frombuffer(text.encode("ascii", "replace"), np.uint8)
        return np.where((c >= FIRST) & (c <= LAST), c, ord("?"))

    @property
    def _tables(self):
        """Per code: advance (px) and atlas box (u0, v0, u1, v1), as arrays (made once)."""
        if not hasattr(self, "_tab"):
            H, W = self.image.shape
            cw, ch = self.cell
            adv = np.zeros(LAST + 1)
            uv = np.zeros((LAST + 1, 4), np.float32)
            for c, (ax, ay) in self.boxes.items():
                adv[ord(c)] = self.advance[c]
                uv[ord(c)] = (ax / W, ay / H, (ax + cw) / W, (ay + ch) / H)
            self._tab = adv, uv
        return self._tab

    def text_width(self, text: str) -> float:
        return float(self._tables[0][self._codes(text)].sum())

    def layout(self, lines) -> tuple[list[float], float, float]:
        """Column offsets (px) of tab-separated lines, and the block's width and height."""
        at, gap = self, 12.0
        cols = [s.split("\t") for s in lines]
        n = max(len(c) for c in cols)
        widths = [max((at.text_width(c[i]) for c in cols if len(c) > i + 1), default=0.0)
                  for i in range(n)]
        offsets = [sum(widths[:i]) + gap * i for i in range(n)]
        w = max(offsets[len(c) - 1] + at.text_width(c[-1]) for c in cols) + 12
        return offsets, w, len(lines) * at.line_height + 8

    #: the six corners of a glyph's two triangles: which of (x0, x1) and (y0, y1) each takes
    _CX = np.array([0, 1, 1, 0, 1, 0])
    _CY = np.array([0, 0, 1, 0, 1, 1])

    def quads(self, text: str, x: float, y: float, color) -> np.ndarray:
        """Vertices (6 per glyph) of ``text`` with its top-left at (x, y) px: pos, uv, color."""
        return self.quads_many([(text, x, y)], color)

    def quads_many(self, runs, color) -> np.ndarray:
        """:meth:`quads` of several (text, x, y) runs at once (one NumPy pass)."""
        adv, uv = self._tables
        runs = [r for r in runs if r[0]]
        if not runs:
            return np.zeros((0, 8), np.float32)
        codes = [self._codes(t) for t, _, _ in runs]
        lens = np.array([len(c) for c in codes])
        codes = np.concatenate(codes)
        run = np.repeat(np.arange(len(runs)), lens)
        ends = np.cumsum(adv[codes])                  # pen position after each glyph
        before = np.concatenate(([0.0], ends[:-1]))   # ... before it
        start = np.concatenate(([0], np.cumsum(lens)[:-1]))
        x0 = np.array([r[1] for r in runs])[run] + before - before[start][run]
        y0 = np.array([r[2] for r in runs], np.float64)[run]
        ink = codes != ord(" ")
        codes, x0, y0 = codes[ink], x0[ink], y0[ink]
        cw, ch = self.cell
        xs = np.stack([x0, x0 + cw], axis=1)[:, self._CX]          # (n, 6)
        ys = np.stack([y0, y0 + ch], axis=1)[:, self._CY]
        box = uv[codes]
        out = np.empty((len(codes), 6, 8), np.float32)
        out[..., 0], out[..., 1] = xs, ys
        out[..., 2], out[..., 3] = box[:, [0, 2]][:, self._CX], box[:, [1, 3]][:, self._CY]
        out[..., 4:] = np.asarray(color, np.float32)
        return out.reshape(-1, 8)


def _rect(x0, y0, x1, y1, u0, v0, u1, v1, color) -> list:
    r, g, b, a = color
    corners = [(x0, y0, u0, v0), (x1, y0, u1, v0), (x1, y1, u1, v1),
               (x0, y0, u0, v0), (x1, y1, u1, v1), (x0, y1, u0, v1)]
    return [v for px, py, u, vv in corners for v in (px, py, u, vv, r, g, b, a)]


class Hud:
    """Draws text blocks over whatever the context's current framebuffer holds."""

    def __init__(self, ctx, size: int = 14):
        self.ctx = ctx
        self.atlas = GlyphAtlas(size)
        a = self.atlas.image
        self.texture = ctx.texture((a.shape[1], a.shape[0]), 1, np.ascontiguousarray(a).tobytes())
        self.texture.filter = (ctx.NEAREST, ctx.NEAREST)
        self.prog = ctx.program(vertex_shader=_VS, fragment_shader=_FS)
        self.prog["atlas"].value = 0
        self.capacity = 0
        self.vbo = None
        self.vao = None
        self._last_key, self._last_n = None, 0

    def _ensure(self, n_vertices: int) -> None:
        if n_vertices <= self.capacity:
            return
        self.capacity = max(4096, 2 * n_vertices)
        if self.vbo is not None:
            self.vao.release()
            self.vbo.release()
        self.vbo = self.ctx.buffer(reserve=self.capacity * 32, dynamic=True)
        self.vao = self.ctx.vertex_array(self.prog, [(self.vbo, "2f 2f 4f", "pos", "uv",
                                                      "color")])

    def block_vertices(self, lines, x, y, color=(1, 1, 1, 1), box=(0, 0, 0, 0.55)):
        """Vertices of a text block (box then glyphs) with its top-left at (x, y) px; a tab
        starts the next column (columns aligned across the block's lines)."""
        at = self.atlas
        if not lines:
            return np.zeros((0, 8), np.float32)
        offsets, w, h = at.layout(lines)
        parts = [np.asarray(_rect(x, y, x + w, y + h, -1, -1, -1, -1, box),
                            np.float32).reshape(-1, 8)]
        runs = [(col, x + 6 + off, y + 4 + k * at.line_height)
                for k, s in enumerate(lines)
                for off, col in zip(offsets, s.split("\t"), strict=False)]
        parts.append(at.quads_many(runs, color))
        return np.concatenate(parts)

    def draw(self, blocks, screen_size) -> None:
        """``blocks``: (lines, x, y[, color]) tuples; negative x or y count from the right or
        bottom edge. Blocks equal to the last call's are not laid out or uploaded again."""
        key = (tuple((tuple(b[0]), *b[1:]) for b in blocks), tuple(screen_size))
        if key == self._last_key:
            self._render(self._last_n, screen_size)
            return
        verts = []
        for blk in blocks:
            lines, x, y = blk[:3]
            color = blk[3] if len(blk) > 3 else (1, 1, 1, 1)
            if not lines:
                continue
            _, w, h = self.atlas.layout(lines)
            x = screen_size[0] + x - w if x < 0 else x
            y = screen_size[1] + y - h if y < 0 else y
            verts.append(self.block_vertices(lines, x, y, color))
        v = np.concatenate(verts) if verts else np.zeros((0, 8), np.float32)
        if len(v):
            self._ensure(len(v))
            self.vbo.write(v.tobytes())
        self._last_key, self._last_n = key, len(v)
        self._render(len(v), screen_size)

    def _render(self, n_vertices: int, screen_size) -> None:
        if not n_vertices:
            return
        self.prog["screen"].value = tuple(float(s) for s in screen_size)
        self.texture.use(0)
        self.ctx.enable(self.ctx.BLEND)
        self.ctx.blend_func = self.ctx.SRC_ALPHA, self.ctx.ONE_MINUS_SRC_ALPHA
        self.vao.render(vertices=n_vertices)
        self.ctx.disable(self.ctx.BLEND)


# ---- what the HUD says (pure) -------------------------------------------------------------------
def hud_lines(stats, *, fps: float, path: str, size=(0, 0), device: str = "",
              quality: str = "", paused: bool = False, rain: float = 0.0, spp: int = 1,
              bounces: int = 0, caustics: str = "", top: int = 6) -> list[str]:
    """The HUD's text from a FrameStats-like record (None before the first frame)."""
    lines = [f"{fps:5.1f} FPS" + ("  [paused]" if paused else "")
             + (f"  rain {rain:g}/s" if rain else "")]
    w, h = size
    cells = getattr(stats, "water_cells", None)
    lines.append(f"{w}x{h}  {spp} spp  {bounces} bounces  "
                 + (f"grid {cells[0]}x{cells[1]}" if cells else "no water" if stats else "")
                 + (f"  caustics {caustics}" if caustics else ""))
    # the path, and on a line of its own why the shared path is not used (app.window)
    shown = [f"display: {part}" if k == 0 else f"  {part}"
             for k, part in enumerate(path.split("; "))]
    if stats is None:   # before the first frame (or a rebuild's): the settings, the path
        return lines + shown
    lines.append(f"{stats.n_triangles:,} triangles  {stats.n_rays / 1e6:.2f} M rays/frame")
    ms = sorted(stats.stage_ms.items(), key=lambda kv: -kv[1])
    kernel = sum(v for _, v in ms)
    lines.append(f"kernels {kernel:.2f} ms  wall {getattr(stats, 'wall_ms', 0.0):.2f} ms")
    for name, v in ms[:top]:
        lines.append(f"  {name}\t{v:.3f} ms")
    lines.append(f"device: {device}")
    lines.extend(shown)
    if quality:
        lines.append(quality)
    return [s for s in lines if s]


def guard_lines(stats) -> list[str]:
    """Warnings when the water solver acted in the last frame (NaN restored, cells limited,
    tau raised); the guard dict is the solver's ``stats()`` for that frame."""
    if stats is None or not stats.guard:
        return []
    g = stats.guard
    out = []
    if g.get("nan"):
        out.append(f"water: non-finite values, checkpoint restored {g.get('restored', 0)}x")
    n = int(g.get("clamped", 0) or 0)
    if n:
        out.append(f"water: {n} cell updates limited (max Froude {g.get('max_froude', 0):.2f})")
    if g.get("damped"):
        out.append(f"water: viscosity raised (tau {g.get('tau', 0):.3f})")
    return out


def help_lines(help_table) -> list[str]:
    """Key and meaning in two aligned columns (a tab between them)."""
    return ["keys and mouse"] + [f"{k}\t{v}" for k, v in help_table]
