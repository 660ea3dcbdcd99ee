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

    def text_width(self, text: str) -> float:
        return sum(self.advance.get(c, self.advance["?"]) for c in text)

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

    def quads(self, text: str, x: float, y: float, color) -> np.ndarray:
        """Vertices (6 per glyph) of ``text`` with its top-left at (x, y) px: pos, uv, color."""
        H, W = self.image.shape
        cw, ch = self.cell
        out = []
        for c in text:
            if c not in self.boxes:
                c = "?"
            if c != " ":
                ax, ay = self.boxes[c]
                u0, v0, u1, v1 = ax / W, ay / H, (ax + cw) / W, (ay + ch) / H
                out += _rect(x, y, x + cw, y + ch, u0, v0, u1, v1, color)
            x += self.advance[c]
        return np.asarray(out, np.float32).reshape(-1, 8)


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
        for k, s in enumerate(lines):
            for off, col in zip(offsets, s.split("\t"), strict=False):
                parts.append(at.quads(col, x + 6 + off, y + 4 + k * at.line_height, color))
        return np.concatenate(parts)

    def draw(self, blocks, screen_size) -> None:
        """``blocks``: (lines, x, y[, color]) tuples; negative x or y count from the right or
        bottom edge."""
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
        if not verts:
            return
        v = np.concatenate(verts)
        self._ensure(len(v))
        self.vbo.write(v.tobytes())
        self.prog["screen"].value = tuple(float(s) for s in screen_size)
        self.texture.use(0)
        self.ctx.enable(self.ctx.BLEND)
        self.ctx.blend_func = self.ctx.SRC_ALPHA, self.ctx.ONE_MINUS_SRC_ALPHA
        self.vao.render(vertices=len(v))
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
    if stats is None:   # before the first frame (or a rebuild's): the settings, the path
        return lines + [f"display: {path}"]
    lines.append(f"{stats.n_triangles:,} triangles  {stats.n_rays / 1e6:.2f} M rays/frame")
    ms = sorted(stats.stage_ms.items(), key=lambda kv: -kv[1])
    kernel = sum(v for _, v in ms)
    lines.append(f"kernels {kernel:.2f} ms  wall {getattr(stats, 'wall_ms', 0.0):.2f} ms")
    for name, v in ms[:top]:
        lines.append(f"  {name}\t{v:.3f} ms")
    lines.append(f"device: {device}")
    lines.append(f"display: {path}")
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
