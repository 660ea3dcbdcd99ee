"""The window's shared display path: device memory that OpenCL writes and GL reads, with no host
copy, through external memory (OpenCL cl_khr_external_memory_opaque_fd, GL
GL_EXT_memory_object_fd, the memory allocated by Vulkan: app.vk_export). The NVIDIA H200's
OpenCL offers these but not cl_khr_gl_sharing (bench/gl_share_probe.py), and PoCL neither.

A ring of ``slots`` buffers of one RGBA8 image each. Per frame (:meth:`ExternalTargets.enqueue`)
the OpenCL queue acquires the next buffer, copies the frame's RGBA8 buffer into it (device to
device) and releases it; after the host has waited for that release
(:meth:`SharedFrame.wait`), GL copies the buffer into the window's texture as a pixel-unpack
buffer (device to device) and draws. GL finishes with a buffer (``ctx.finish()``) before OpenCL
writes it again. Entry points that pip's pyopencl and moderngl do not bind are called through
ctypes; the OpenCL objects are wrapped as pyopencl objects (``from_int_ptr``).
"""

from __future__ import annotations

import ctypes
import ctypes.util

import pyopencl as cl

from app.cl_ctypes import error_name, loader
from app.errors import LbwaterError

CL_EXTERNAL_MEMORY_HANDLE_OPAQUE_FD_KHR = 0x2060
CL_DEVICE_UUID_KHR = 0x106A
CL_MEM_READ_WRITE = 1 << 0
GL_HANDLE_TYPE_OPAQUE_FD_EXT = 0x9586
GL_PIXEL_UNPACK_BUFFER = 0x88EC
GL_TEXTURE_2D, GL_RGBA, GL_UNSIGNED_BYTE, GL_UNPACK_ALIGNMENT = 0x0DE1, 0x1908, 0x1401, 0x0CF5
GL_EXTENSIONS, GL_NUM_EXTENSIONS = 0x1F03, 0x821D
CL_EXTENSIONS = ("cl_khr_external_memory", "cl_khr_external_memory_opaque_fd")
GL_EXTENSIONS_NEEDED = ("GL_EXT_memory_object", "GL_EXT_memory_object_fd")


class ExternalShareError(LbwaterError):
    """The external-memory path cannot be set up here (one line: why)."""


def missing_cl(device: cl.Device) -> list[str]:
    """The OpenCL extensions this path needs that ``device`` lacks."""
    have = set(device.extensions.split()) | set(device.platform.extensions.split())
    return [e for e in CL_EXTENSIONS if e not in have]


def missing_gl(gl_ctx) -> list[str]:
    """The GL extensions this path needs that the moderngl context ``gl_ctx`` lacks."""
    have = set(gl_ctx.extensions)
    return [e for e in GL_EXTENSIONS_NEEDED if e not in have]


def device_uuid(device: cl.Device) -> bytes:
    """``CL_DEVICE_UUID_KHR`` (cl_khr_device_uuid) of ``device``."""
    lib = loader()
    lib.clGetDeviceInfo.restype = ctypes.c_int32
    lib.clGetDeviceInfo.argtypes = [ctypes.c_void_p, ctypes.c_uint32, ctypes.c_size_t,
                                    ctypes.c_void_p, ctypes.c_void_p]
    raw = (ctypes.c_ubyte * 16)()
    err = lib.clGetDeviceInfo(device.int_ptr, CL_DEVICE_UUID_KHR, 16, raw, None)
    if err != 0:
        raise ExternalShareError(f"{device.name.strip()} reports no device UUID "
                                 f"({error_name(err)})")
    return bytes(raw)


class _Gl:
    """The GL entry points of GL_EXT_memory_object(_fd) and the unpack upload, from the current
    context's loader (EGL, else GLX)."""

    def __init__(self):
        self._get = self._proc_address_loader()
        vp, u32, i32, u64, i64 = (ctypes.c_void_p, ctypes.c_uint32, ctypes.c_int32,
                                  ctypes.c_uint64, ctypes.c_int64)
        self.create_memory = self._fn("glCreateMemoryObjectsEXT", None, i32, vp)
        self.import_fd = self._fn("glImportMemoryFdEXT", None, u32, u64, u32, i32)
        self.delete_memory = self._fn("glDeleteMemoryObjectsEXT", None, i32, vp)
        self.gen_buffers = self._fn("glGenBuffers", None, i32, vp)
        self.delete_buffers = self._fn("glDeleteBuffers", None, i32, vp)
        self.bind_buffer = self._fn("glBindBuffer", None, u32, u32)
        self.buffer_storage_mem = self._fn("glBufferStorageMemEXT", None, u32, i64, u32, u64)
        self.bind_texture = self._fn("glBindTexture", None, u32, u32)
        self.pixel_store = self._fn("glPixelStorei", None, u32, i32)
        self.tex_sub_image = self._fn("glTexSubImage2D", None, u32, i32, i32, i32, i32, i32,
                                      u32, u32, vp)
        self.get_error = self._fn("glGetError", u32)

    @staticmethod
    def _proc_address_loader():
        for lib, name in (("EGL", "eglGetProcAddress"), ("GL", "glXGetProcAddressARB")):
            try:
                f = getattr(ctypes.CDLL(ctypes.util.find_library(lib) or f"lib{lib}.so.1"),
                            name)
            except (OSError, AttributeError):
                continue
            f.restype, f.argtypes = ctypes.c_void_p, [ctypes.c_char_p]
            return f
        raise ExternalShareError("no EGL or GLX loader for the GL entry points")

    def _fn(self, name: str, restype, *argtypes):
        addr = self._get(name.encode())
        if not addr:
            raise ExternalShareError(f"GL has no {name}")
        return ctypes.CFUNCTYPE(restype, *argtypes)(addr)


class SharedFrame:
    """One frame copied into a shared buffer: :meth:`wait` for its release, then
    :meth:`upload_into` a moderngl texture (device to device)."""

    __slots__ = ("event", "_targets", "_slot")

    def __init__(self, event: cl.Event, targets: ExternalTargets, slot: int):
        self.event, self._targets, self._slot = event, targets, slot

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of the frame."""
        return self._targets.size

    def wait(self) -> SharedFrame:
        self.event.wait()
        return self

    def upload_into(self, texture) -> None:
        """GL: the frame's buffer into ``texture`` (same size, RGBA8), no host copy."""
        self._targets.upload(self._slot, texture)


class ExternalTargets:
    """``slots`` RGBA8 frames of ``size`` (width, height) in memory shared by the OpenCL
    context of ``rt`` and the current GL context ``gl_ctx`` (moderngl)."""

    def __init__(self, gl_ctx, rt, size: tuple[int, int], slots: int = 2):
        from app.vk_export import VulkanError, exporter

        miss = missing_cl(rt.device)
        if miss:
            raise ExternalShareError(f"no {' and '.join(miss)} on {rt.device.name.strip()}")
        miss = missing_gl(gl_ctx)
        if miss:
            raise ExternalShareError(f"GL lacks {' and '.join(miss)}")
        self.gl, self.rt = gl_ctx, rt
        self.size = (int(size[0]), int(size[1]))
        self.nbytes = self.size[0] * self.size[1] * 4
        lib = self._lib = loader()
        plat = rt.device.platform
        lib.clGetExtensionFunctionAddressForPlatform.restype = ctypes.c_void_p
        lib.clGetExtensionFunctionAddressForPlatform.argtypes = [ctypes.c_void_p,
                                                                 ctypes.c_char_p]
        proto = ctypes.CFUNCTYPE(ctypes.c_int32, ctypes.c_void_p, ctypes.c_uint32,
                                 ctypes.c_void_p, ctypes.c_uint32, ctypes.c_void_p,
                                 ctypes.c_void_p)
        self._acquire_release = []
        for name in ("clEnqueueAcquireExternalMemObjectsKHR",
                     "clEnqueueReleaseExternalMemObjectsKHR"):
            addr = lib.clGetExtensionFunctionAddressForPlatform(plat.int_ptr, name.encode())
            if not addr:
                raise ExternalShareError(f"the OpenCL platform has no {name}")
            self._acquire_release.append(proto(addr))
        lib.clCreateBufferWithProperties.restype = ctypes.c_void_p
        lib.clCreateBufferWithProperties.argtypes = [
            ctypes.c_void_p, ctypes.c_void_p, ctypes.c_uint64, ctypes.c_size_t,
            ctypes.c_void_p, ctypes.POINTER(ctypes.c_int32)]
        self._gl = _Gl()
        self.memories, self.buffers, self.gl_buffers, self.gl_memories = [], [], [], []
        self._vk = None
        self._drawn = [False] * slots
        self._next = 0
        try:
            self._vk = exporter(device_uuid(rt.device))
            for _ in range(slots):
                self._add_slot(self._vk.allocate(self.nbytes))
        except VulkanError as exc:
            self.release()
            raise ExternalShareError(str(exc)) from None
        except BaseException:
            self.release()
            raise

    def _add_slot(self, mem: int) -> None:
        self.memories.append(mem)
        props = (ctypes.c_uint64 * 3)(CL_EXTERNAL_MEMORY_HANDLE_OPAQUE_FD_KHR,
                                      self._vk.export_fd(mem), 0)
        err = ctypes.c_int32(0)
        ptr = self._lib.clCreateBufferWithProperties(
            self.rt.context.int_ptr, ctypes.cast(props, ctypes.c_void_p), CL_MEM_READ_WRITE,
            self.nbytes, None, ctypes.byref(err))
        if err.value != 0 or not ptr:
            raise ExternalShareError(f"OpenCL could not import the shared memory "
                                     f"({error_name(err.value)})")
        self.buffers.append(cl.Buffer.from_int_ptr(ptr, retain=False))
        g = self._gl
        code = g.get_error()
        if code:
            raise RuntimeError(f"a GL error was pending before the import (0x{code:04x})")
        gl_mem = ctypes.c_uint32(0)
        g.create_memory(1, ctypes.byref(gl_mem))
        g.import_fd(gl_mem.value, self.nbytes, GL_HANDLE_TYPE_OPAQUE_FD_EXT,
                    self._vk.export_fd(mem))
        buf = ctypes.c_uint32(0)
        g.gen_buffers(1, ctypes.byref(buf))
        g.bind_buffer(GL_PIXEL_UNPACK_BUFFER, buf.value)
        g.buffer_storage_mem(GL_PIXEL_UNPACK_BUFFER, self.nbytes, gl_mem.value, 0)
        g.bind_buffer(GL_PIXEL_UNPACK_BUFFER, 0)
        self.gl_memories.append(gl_mem.value)
        self.gl_buffers.append(buf.value)
        code = g.get_error()
        if code:
            raise ExternalShareError(f"GL could not import the shared memory (GL error "
                                     f"0x{code:04x})")

    def _enqueue_ext(self, which: int, queue: cl.CommandQueue, mem: cl.Buffer) -> cl.Event:
        objs = (ctypes.c_void_p * 1)(mem.int_ptr)
        evt = ctypes.c_void_p()
        err = self._acquire_release[which](queue.int_ptr, 1, ctypes.cast(objs, ctypes.c_void_p),
                                           0, None, ctypes.cast(ctypes.byref(evt),
                                                                ctypes.c_void_p))
        if err != 0:
            raise RuntimeError(f"{('acquire', 'release')[which]} of external memory failed "
                               f"({error_name(err)})")
        return cl.Event.from_int_ptr(evt.value, retain=False)

    def enqueue(self, queue: cl.CommandQueue, rgba: cl.Buffer) -> SharedFrame:
        """Queue the copy of ``rgba`` (RGBA8, row 0 on top) into the next shared buffer."""
        k = self._next
        self._next = (k + 1) % len(self.buffers)
        if self._drawn[k]:
            self.gl.finish()   # GL's reads of this buffer done before OpenCL writes it
            self._drawn = [False] * len(self._drawn)
        buf = self.buffers[k]
        self._enqueue_ext(0, queue, buf)
        cl.enqueue_copy(queue, buf, rgba, byte_count=self.nbytes)
        return SharedFrame(self._enqueue_ext(1, queue, buf), self, k)

    def upload(self, slot: int, texture) -> None:
        g = self._gl
        w, h = self.size
        g.bind_buffer(GL_PIXEL_UNPACK_BUFFER, self.gl_buffers[slot])
        g.bind_texture(GL_TEXTURE_2D, texture.glo)
        g.pixel_store(GL_UNPACK_ALIGNMENT, 1)
        g.tex_sub_image(GL_TEXTURE_2D, 0, 0, 0, w, h, GL_RGBA, GL_UNSIGNED_BYTE, None)
        g.bind_buffer(GL_PIXEL_UNPACK_BUFFER, 0)
        code = g.get_error()
        if code:
            raise RuntimeError(f"GL upload from the shared buffer failed (GL error 0x{code:04x})")
        self._drawn[slot] = True

    def release(self) -> list[tuple[str, int]]:
        """Free the GL, OpenCL and Vulkan objects, each API done with the memory before its
        allocation is freed; returns the GL errors seen while doing so."""
        g = getattr(self, "_gl", None)
        errors = []
        if g is not None:
            self.gl.finish()
            for step, ids, delete in (("buffers", self.gl_buffers, g.delete_buffers),
                                      ("memory", self.gl_memories, g.delete_memory)):
                for i in ids:
                    delete(1, ctypes.byref(ctypes.c_uint32(i)))
                    code = g.get_error()
                    if code:
                        errors.append((step, code))
            self.gl.finish()
        self.gl_buffers, self.gl_memories = [], []
        if self.buffers:
            self.rt.queue.finish()
            for b in self.buffers:
                b.release()
        self.buffers = []
        if self._vk is not None:
            for m in self.memories:
                self._vk.free(m)
            self._vk = None   # the process-wide exporter stays (app.vk_export.exporter)
        self.memories = []
        return errors
