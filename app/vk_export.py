"""Exportable device memory from Vulkan (ctypes): the allocator behind the window's shared
display path (app.ext_share), since neither OpenCL nor GL can export memory themselves.

:class:`Exporter` opens the Vulkan device whose UUID is given (the OpenCL device's
``CL_DEVICE_UUID_KHR``), makes ``VK_EXTERNAL_MEMORY_HANDLE_TYPE_OPAQUE_FD`` allocations of its
device-local memory and hands out file descriptors of them that OpenCL
(cl_khr_external_memory_opaque_fd) and GL (GL_EXT_memory_object_fd) import. Only the few entry
points this needs are bound.
"""

from __future__ import annotations

import ctypes
import ctypes.util

from app.errors import LbwaterError

VK_SUCCESS = 0
_API_1_1 = (1 << 22) | (1 << 12)
_ST_APPLICATION_INFO, _ST_INSTANCE_CREATE_INFO = 0, 1
_ST_DEVICE_QUEUE_CREATE_INFO, _ST_DEVICE_CREATE_INFO, _ST_MEMORY_ALLOCATE_INFO = 2, 3, 5
_ST_PHYSICAL_DEVICE_PROPERTIES_2 = 1000059001
_ST_PHYSICAL_DEVICE_ID_PROPERTIES = 1000071004
_ST_EXPORT_MEMORY_ALLOCATE_INFO = 1000072002
_ST_MEMORY_GET_FD_INFO_KHR = 1000074002
HANDLE_TYPE_OPAQUE_FD = 0x1
_MEMORY_PROPERTY_DEVICE_LOCAL = 0x1

_vp, _u32, _u64 = ctypes.c_void_p, ctypes.c_uint32, ctypes.c_uint64


class VulkanError(LbwaterError):
    """Vulkan is missing or refused a step (one line: which step and its VkResult)."""


class _AppInfo(ctypes.Structure):
    _fields_ = [("sType", _u32), ("pNext", _vp), ("pApplicationName", ctypes.c_char_p),
                ("applicationVersion", _u32), ("pEngineName", ctypes.c_char_p),
                ("engineVersion", _u32), ("apiVersion", _u32)]


class _InstanceInfo(ctypes.Structure):
    _fields_ = [("sType", _u32), ("pNext", _vp), ("flags", _u32), ("pApplicationInfo", _vp),
                ("enabledLayerCount", _u32), ("ppEnabledLayerNames", _vp),
                ("enabledExtensionCount", _u32), ("ppEnabledExtensionNames", _vp)]


class _IdProperties(ctypes.Structure):
    _fields_ = [("sType", _u32), ("pNext", _vp), ("deviceUUID", ctypes.c_ubyte * 16),
                ("driverUUID", ctypes.c_ubyte * 16), ("deviceLUID", ctypes.c_ubyte * 8),
                ("deviceNodeMask", _u32), ("deviceLUIDValid", _u32)]


class _Properties2(ctypes.Structure):
    # VkPhysicalDeviceProperties (824 bytes on 64-bit) is kept as opaque bytes, with room
    _fields_ = [("sType", _u32), ("pNext", _vp), ("properties", ctypes.c_ubyte * 1024)]


class _QueueInfo(ctypes.Structure):
    _fields_ = [("sType", _u32), ("pNext", _vp), ("flags", _u32), ("queueFamilyIndex", _u32),
                ("queueCount", _u32), ("pQueuePriorities", ctypes.POINTER(ctypes.c_float))]


class _DeviceInfo(ctypes.Structure):
    _fields_ = [("sType", _u32), ("pNext", _vp), ("flags", _u32),
                ("queueCreateInfoCount", _u32), ("pQueueCreateInfos", _vp),
                ("enabledLayerCount", _u32), ("ppEnabledLayerNames", _vp),
                ("enabledExtensionCount", _u32), ("ppEnabledExtensionNames", _vp),
                ("pEnabledFeatures", _vp)]


class _MemoryType(ctypes.Structure):
    _fields_ = [("propertyFlags", _u32), ("heapIndex", _u32)]


class _MemoryHeap(ctypes.Structure):
    _fields_ = [("size", _u64), ("flags", _u32)]


class _MemoryProperties(ctypes.Structure):
    _fields_ = [("memoryTypeCount", _u32), ("memoryTypes", _MemoryType * 32),
                ("memoryHeapCount", _u32), ("memoryHeaps", _MemoryHeap * 16)]


class _ExportInfo(ctypes.Structure):
    _fields_ = [("sType", _u32), ("pNext", _vp), ("handleTypes", _u32)]


class _AllocateInfo(ctypes.Structure):
    _fields_ = [("sType", _u32), ("pNext", _vp), ("allocationSize", _u64),
                ("memoryTypeIndex", _u32)]


class _GetFdInfo(ctypes.Structure):
    _fields_ = [("sType", _u32), ("pNext", _vp), ("memory", _u64), ("handleType", _u32)]


def _vulkan() -> ctypes.CDLL:
    name = ctypes.util.find_library("vulkan") or "libvulkan.so.1"
    try:
        return ctypes.CDLL(name)
    except OSError:
        raise VulkanError("no Vulkan loader (libvulkan.so.1) to allocate shared memory") \
            from None


def _check(result: int, step: str) -> None:
    if result != VK_SUCCESS:
        raise VulkanError(f"Vulkan {step} failed (VkResult {result})")


class Exporter:
    """A Vulkan device (the one with ``uuid``) that makes exportable device-local allocations."""

    def __init__(self, uuid: bytes):
        vk = self._vk = _vulkan()
        for name, res, args in (
                ("vkCreateInstance", ctypes.c_int32, [_vp, _vp, _vp]),
                ("vkEnumeratePhysicalDevices", ctypes.c_int32, [_vp, _vp, _vp]),
                ("vkGetPhysicalDeviceProperties2", None, [_vp, _vp]),
                ("vkGetPhysicalDeviceQueueFamilyProperties", None, [_vp, _vp, _vp]),
                ("vkGetPhysicalDeviceMemoryProperties", None, [_vp, _vp]),
                ("vkCreateDevice", ctypes.c_int32, [_vp, _vp, _vp, _vp]),
                ("vkGetDeviceProcAddr", _vp, [_vp, ctypes.c_char_p]),
                ("vkAllocateMemory", ctypes.c_int32, [_vp, _vp, _vp, _vp]),
                ("vkFreeMemory", None, [_vp, _u64, _vp]),
                ("vkDestroyDevice", None, [_vp, _vp]),
                ("vkDestroyInstance", None, [_vp, _vp])):
            f = getattr(vk, name)
            f.restype, f.argtypes = res, args
        app = _AppInfo(_ST_APPLICATION_INFO, None, b"lbwater", 1, b"lbwater", 1, _API_1_1)
        info = _InstanceInfo(_ST_INSTANCE_CREATE_INFO, None, 0,
                             ctypes.cast(ctypes.pointer(app), _vp), 0, None, 0, None)
        self.instance = _vp()
        _check(vk.vkCreateInstance(ctypes.byref(info), None, ctypes.byref(self.instance)),
               "vkCreateInstance")
        self.device = None
        self.memory_type = None
        try:
            self.physical = self._find(uuid)
            self._create_device()
        except BaseException:
            self.close()
            raise

    def _find(self, uuid: bytes):
        vk = self._vk
        n = _u32(0)
        _check(vk.vkEnumeratePhysicalDevices(self.instance, ctypes.byref(n), None),
               "vkEnumeratePhysicalDevices")
        devs = (_vp * n.value)()
        _check(vk.vkEnumeratePhysicalDevices(self.instance, ctypes.byref(n), devs),
               "vkEnumeratePhysicalDevices")
        for pd in devs[: n.value]:
            ids = _IdProperties(_ST_PHYSICAL_DEVICE_ID_PROPERTIES, None)
            props = _Properties2(_ST_PHYSICAL_DEVICE_PROPERTIES_2,
                                 ctypes.cast(ctypes.pointer(ids), _vp))
            vk.vkGetPhysicalDeviceProperties2(pd, ctypes.byref(props))
            if bytes(ids.deviceUUID) == bytes(uuid):
                return pd
        raise VulkanError(f"no Vulkan device has the OpenCL device's UUID {bytes(uuid).hex()} "
                          f"({n.value} Vulkan devices)")

    def _create_device(self) -> None:
        vk = self._vk
        prio = (ctypes.c_float * 1)(1.0)
        queue = _QueueInfo(_ST_DEVICE_QUEUE_CREATE_INFO, None, 0, 0, 1, prio)
        exts = (ctypes.c_char_p * 2)(b"VK_KHR_external_memory", b"VK_KHR_external_memory_fd")
        info = _DeviceInfo(_ST_DEVICE_CREATE_INFO, None, 0, 1,
                           ctypes.cast(ctypes.pointer(queue), _vp), 0, None, 2,
                           ctypes.cast(exts, _vp), None)
        self.device = _vp()
        _check(vk.vkCreateDevice(self.physical, ctypes.byref(info), None,
                                 ctypes.byref(self.device)), "vkCreateDevice")
        addr = vk.vkGetDeviceProcAddr(self.device, b"vkGetMemoryFdKHR")
        if not addr:
            raise VulkanError("Vulkan device lacks vkGetMemoryFdKHR")
        self._get_fd = ctypes.CFUNCTYPE(ctypes.c_int32, _vp, _vp,
                                        ctypes.POINTER(ctypes.c_int))(addr)

    def allocate(self, size: int) -> int:
        """A new exportable allocation of ``size`` bytes; its VkDeviceMemory handle."""
        vk = self._vk
        if self.memory_type is None:
            mp = _MemoryProperties()
            vk.vkGetPhysicalDeviceMemoryProperties(self.physical, ctypes.byref(mp))
            self.memory_type = next(
                (i for i in range(mp.memoryTypeCount)
                 if mp.memoryTypes[i].propertyFlags & _MEMORY_PROPERTY_DEVICE_LOCAL), None)
            if self.memory_type is None:
                raise VulkanError("no device-local Vulkan memory type")
        export = _ExportInfo(_ST_EXPORT_MEMORY_ALLOCATE_INFO, None, HANDLE_TYPE_OPAQUE_FD)
        info = _AllocateInfo(_ST_MEMORY_ALLOCATE_INFO, ctypes.cast(ctypes.pointer(export), _vp),
                             int(size), self.memory_type)
        mem = _u64(0)
        _check(vk.vkAllocateMemory(self.device, ctypes.byref(info), None, ctypes.byref(mem)),
               "vkAllocateMemory")
        return mem.value

    def export_fd(self, memory: int) -> int:
        """A new file descriptor of ``memory`` (the importer takes ownership of it)."""
        fd = ctypes.c_int(-1)
        info = _GetFdInfo(_ST_MEMORY_GET_FD_INFO_KHR, None, memory, HANDLE_TYPE_OPAQUE_FD)
        _check(self._get_fd(self.device, ctypes.byref(info), ctypes.byref(fd)),
               "vkGetMemoryFdKHR")
        return fd.value

    def free(self, memory: int) -> None:
        """Free ``memory`` (once its importers are done with it)."""
        self._vk.vkFreeMemory(self.device, memory, None)

    def close(self) -> None:
        """Destroy the Vulkan device and instance (free the allocations first)."""
        vk = self._vk
        if self.device:
            vk.vkDestroyDevice(self.device, None)
            self.device = None
        if self.instance:
            vk.vkDestroyInstance(self.instance, None)
            self.instance = None


_exporters: dict[bytes, Exporter] = {}


def exporter(uuid: bytes) -> Exporter:
    """The process's one :class:`Exporter` for the device ``uuid``, made on first use and kept
    until exit: on the NVIDIA driver, destroying a Vulkan instance left the thread's EGL context
    no longer current (bench/gl_share_probe.py on the H200, 2026-12-01)."""
    key = bytes(uuid)
    if key not in _exporters:
        _exporters[key] = Exporter(key)
    return _exporters[key]
