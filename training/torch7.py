"""A reader for Torch7's binary serialisation format (``torch.save`` / ``torch.load`` files,
``.t7`` / ``.net``), written from the format's description, for loading Lua Torch models
(such as e-lab's ENet) into Python without Lua.

The format is a stream of objects, each starting with a 4-byte type tag:

====  ==================  ===========================================================
tag   type                payload
====  ==================  ===========================================================
0     nil                 nothing
1     number              float64
2     string              int32 length, bytes
3     table               int32 reference index; (first occurrence) int32 entry count,
                          then key object, value object per entry
4     torch class         int32 reference index; (first occurrence) version string
                          ("V <n>", then the class name as a second string; legacy files
                          put the class name directly), then the class's payload
5     boolean             int32 (1 = true)
6, 8  function            int32 reference index; bytecode string, upvalues object
7     legacy function     as 6/8, the older recursive encoding
====  ==================  ===========================================================

A reference index that was seen before stands for the object already read (shared or cyclic
references). Tensors (``torch.*Tensor``) carry int32 ndim, ndim int64 sizes, ndim int64
strides, an int64 1-based storage offset and their storage as an object; storages
(``torch.*Storage``) an int64 element count and the raw little-endian elements. Every other
torch class (``nn.*``, ``cudnn.*``) carries one object, its table of fields.

``read_torch7(path)`` returns plain Python objects: None, float (numbers; an integral
number stays a float, as in Lua), str, bool, dict (tables; see ``table_as_list``), numpy
arrays (tensors and storages) and :class:`TorchObject` (the other torch classes, with
``.typename`` and ``.fields``).
"""

from __future__ import annotations

import struct
from typing import Any, Dict, List, Optional

import numpy as np

__all__ = ["TorchObject", "TorchFunction", "Torch7FormatError", "read_torch7", "table_as_list",
           "walk"]

TYPE_NIL = 0
TYPE_NUMBER = 1
TYPE_STRING = 2
TYPE_TABLE = 3
TYPE_TORCH = 4
TYPE_BOOLEAN = 5
TYPE_FUNCTION = 6
TYPE_RECUR_FUNCTION = 8
LEGACY_TYPE_RECUR_FUNCTION = 7

# Element types of tensors/storages by the class name's prefix (torch.<Prefix>Tensor).
# Cuda types are stored like their CPU counterparts (CudaTensor = float32).
_ELEMENT_TYPES = {
    "Double": np.float64,
    "Float": np.float32,
    "Half": np.float16,
    "Byte": np.uint8,
    "Char": np.int8,
    "Short": np.int16,
    "Int": np.int32,
    "Long": np.int64,
    "CudaDouble": np.float64,
    "Cuda": np.float32,
    "CudaHalf": np.float16,
    "CudaByte": np.uint8,
    "CudaChar": np.int8,
    "CudaShort": np.int16,
    "CudaInt": np.int32,
    "CudaLong": np.int64,
}


class Torch7FormatError(ValueError):
    """The stream is not (or not supported) Torch7 binary serialisation."""


class TorchObject:
    """An instance of a Torch class other than a tensor or storage (``nn.*``, ``cudnn.*``,
    ...): its class name and its field table (keys are field names)."""

    __slots__ = ("typename", "version", "fields")

    def __init__(self, typename: str, version: int, fields: Optional[Dict[Any, Any]] = None):
        self.typename = typename
        self.version = version
        self.fields = fields if fields is not None else {}

    def get(self, key: str, default: Any = None) -> Any:
        return self.fields.get(key, default)

    def __getitem__(self, key: str) -> Any:
        return self.fields[key]

    def __contains__(self, key: str) -> bool:
        return key in self.fields

    def __repr__(self) -> str:
        return f"TorchObject({self.typename!r}, fields={sorted(map(str, self.fields))})"


class TorchFunction:
    """A serialised Lua function (dumped bytecode and upvalues); kept, never run."""

    __slots__ = ("bytecode", "upvalues")

    def __init__(self, bytecode: bytes, upvalues: Any):
        self.bytecode = bytecode
        self.upvalues = upvalues

    def __repr__(self) -> str:
        return f"TorchFunction({len(self.bytecode)} bytes)"


class _Reader:
    def __init__(self, data: bytes, long_size: int = 8):
        if long_size not in (4, 8):
            raise ValueError("long_size must be 4 or 8")
        self.data = data
        self.pos = 0
        self.long_size = long_size
        self.objects: Dict[int, Any] = {}

    # --- primitives -------------------------------------------------------------------
    def _take(self, n: int) -> bytes:
        end = self.pos + n
        if n < 0 or end > len(self.data):
            raise Torch7FormatError(
                f"unexpected end of data at byte {self.pos} (wanted {n} more bytes)")
        chunk = self.data[self.pos:end]
        self.pos = end
        return chunk

    def int(self) -> int:
        return struct.unpack("<i", self._take(4))[0]

    def long(self) -> int:
        return struct.unpack("<q" if self.long_size == 8 else "<i", self._take(self.long_size))[0]

    def longs(self, n: int) -> List[int]:
        fmt = ("<%dq" if self.long_size == 8 else "<%di") % n
        return list(struct.unpack(fmt, self._take(self.long_size * n)))

    def double(self) -> float:
        return struct.unpack("<d", self._take(8))[0]

    def string(self) -> str:
        n = self.int()
        return self._take(n).decode("latin-1")

    def raw_string(self) -> bytes:
        n = self.int()
        return self._take(n)

    # --- objects ----------------------------------------------------------------------
    def object(self) -> Any:
        start = self.pos
        tag = self.int()
        if tag == TYPE_NIL:
            return None
        if tag == TYPE_NUMBER:
            return self.double()
        if tag == TYPE_STRING:
            return self.string()
        if tag == TYPE_BOOLEAN:
            return self.int() == 1
        if tag in (TYPE_TABLE, TYPE_TORCH, TYPE_FUNCTION, TYPE_RECUR_FUNCTION,
                   LEGACY_TYPE_RECUR_FUNCTION):
            index = self.int()
            if index in self.objects:
                return self.objects[index]
            if tag == TYPE_TABLE:
                return self._table(index)
            if tag == TYPE_TORCH:
                return self._torch(index)
            return self._function(index)
        raise Torch7FormatError(f"unknown type tag {tag} at byte {start}")

    def _table(self, index: int) -> Dict[Any, Any]:
        table: Dict[Any, Any] = {}
        self.objects[index] = table  # before the entries: they may refer to the table
        for _ in range(self.int()):
            key = self.object()
            value = self.object()
            if isinstance(key, float) and key.is_integer():
                key = int(key)  # Lua array part: 1-based integer keys
            table[key] = value
        return table

    def _function(self, index: int) -> TorchFunction:
        fn = TorchFunction(self.raw_string(), None)
        self.objects[index] = fn
        fn.upvalues = self.object()
        return fn

    def _torch(self, index: int) -> Any:
        version_string = self.string()
        if version_string.startswith("V "):
            version = int(version_string[2:])
            class_name = self.string()
        else:
            version, class_name = 0, version_string
        kind, element = _classify(class_name)
        if kind == "tensor":
            return self._tensor(index, class_name, element)
        if kind == "storage":
            return self._storage(index, class_name, element)
        obj = TorchObject(class_name, version)
        self.objects[index] = obj
        fields = self.object()
        if isinstance(fields, dict):
            obj.fields = fields
        else:  # a class serialising something other than a table: keep it under one key
            obj.fields = {"_value": fields}
        return obj

    def _tensor(self, index: int, class_name: str, element: Any) -> np.ndarray:
        ndim = self.int()
        sizes = self.longs(ndim)
        strides = self.longs(ndim)
        offset = self.long() - 1  # 1-based
        storage = self.object()
        if ndim == 0 or storage is None or any(s == 0 for s in sizes):
            array = np.zeros(sizes if ndim else (0,), dtype=element)
        else:
            if not isinstance(storage, np.ndarray):
                raise Torch7FormatError(f"{class_name} without a storage array")
            extent = offset + 1 + sum((n - 1) * s for n, s in zip(sizes, strides))
            if offset < 0 or extent > storage.size or any(s < 0 for s in strides):
                raise Torch7FormatError(
                    f"{class_name} of sizes {sizes} strides {strides} offset {offset} does not fit "
                    f"its storage of {storage.size} elements")
            itemsize = storage.dtype.itemsize
            array = np.lib.stride_tricks.as_strided(
                storage[offset:], shape=sizes, strides=[s * itemsize for s in strides]).copy()
        self.objects[index] = array
        return array

    def _storage(self, index: int, class_name: str, element: Any) -> np.ndarray:
        n = self.long()
        dtype = np.dtype(element).newbyteorder("<")
        array = np.frombuffer(self._take(n * dtype.itemsize), dtype=dtype).astype(element)
        self.objects[index] = array
        return array


def _classify(class_name: str):
    """('tensor' | 'storage' | 'object', numpy element type or None)."""
    if class_name.startswith("torch."):
        name = class_name[len("torch."):]
        for suffix, kind in (("Tensor", "tensor"), ("Storage", "storage")):
            if name.endswith(suffix):
                prefix = name[:-len(suffix)]
                if prefix in _ELEMENT_TYPES:
                    return kind, _ELEMENT_TYPES[prefix]
    return "object", None


def read_torch7(path: str, long_size: int = 8) -> Any:
    """Reads one object (normally the model) from a Torch7 binary file.

    Returns Python objects as described in the module docstring. ``long_size`` is the size
    of C ``long`` on the machine that wrote the file (8 on 64-bit Linux/macOS).
    """
    with open(path, "rb") as f:
        data = f.read()
    reader = _Reader(data, long_size)
    obj = reader.object()
    return obj


def table_as_list(table: Any) -> List[Any]:
    """A Lua array-like table (keys 1..n) as a Python list; a list passes through."""
    if table is None:
        return []
    if isinstance(table, list):
        return table
    if not isinstance(table, dict):
        raise TypeError(f"not a table: {type(table).__name__}")
    n = len(table)
    if set(table) != set(range(1, n + 1)):
        raise ValueError(f"table is not a 1..n array (keys {sorted(map(str, table))[:8]}...)")
    return [table[i] for i in range(1, n + 1)]


def walk(module: TorchObject, depth: int = 0):
    """Yields (depth, module) over an nn module tree, depth first, containers first."""
    yield depth, module
    if isinstance(module, TorchObject) and "modules" in module.fields:
        for child in table_as_list(module.fields["modules"]):
            yield from walk(child, depth + 1)


if __name__ == "__main__":  # python3 torch7.py FILE: prints the module tree
    import sys

    root = read_torch7(sys.argv[1])
    for d, m in walk(root):
        if not isinstance(m, TorchObject):
            print("  " * d + repr(m))
            continue
        desc = {k: v for k, v in m.fields.items()
                if isinstance(v, (int, float, bool, str)) and not str(k).startswith("_")}
        shapes = {k: tuple(v.shape) for k, v in m.fields.items()
                  if isinstance(v, np.ndarray) and v.size and k in ("weight", "bias",
                                                                    "running_mean",
                                                                    "running_var")}
        print("  " * d + m.typename, desc, shapes)
