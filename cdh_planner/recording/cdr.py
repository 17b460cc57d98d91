"""CDR encoding of ROS 2 messages from their definition text, through rosbags' public
typestore (``get_types_from_msg``, ``Typestore.serialize_cdr``): exact sizes, no padding
beyond the message (unlike ``rclpy.serialization``), so rosbag2, Foxglove, mcap_ros2 and
rosbags all read the bytes. No rclpy.

    encoders = CdrEncoders()
    encode = encoders.encoder("sensor_msgs/msg/JointState", full_definition_text)
    data = encode(plain)     # plain: recording.ros_schemas.encodable's dicts, lists, bytes, scalars

rosbags builds its message classes from the text; ``plain`` is shaped into them by the
field definitions (primitive arrays as numpy arrays of the field's type; ``char`` values,
signed or not, as the unsigned byte ROS 2 says they are).
"""

import threading

import numpy as np
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

DTYPES = {"bool": np.bool_, "byte": np.uint8, "char": np.uint8, "octet": np.uint8,
          "int8": np.int8, "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16,
          "int32": np.int32, "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64,
          "float32": np.float32, "float64": np.float64}
TEXT = ("string", "wstring")
EMPTY_MEMBER = "structure_needs_at_least_one_member"


class CdrEncoders:
    """Encoders of the types registered so far (one typestore: one definition per name)."""

    def __init__(self):
        self._store = get_typestore(Stores.EMPTY)
        self._lock = threading.Lock()

    def encoder(self, type_name, text):
        """A function: plain data of ``type_name`` -> its CDR bytes (little endian).
        ``text``: the type's definition with its dependencies (rosbag2's ros2msg layout)."""
        with self._lock:
            self._store.register(get_types_from_msg(text, type_name))
        store = self._store

        def encode(plain):
            return bytes(store.serialize_cdr(self._build(type_name, plain), type_name))
        return encode

    def _build(self, type_name, plain):
        _, fields = self._store.fielddefs[type_name]
        values = {}
        for name, (kind, detail) in fields:
            if name == EMPTY_MEMBER and name not in plain:
                values[name] = 0          # rosidl's one member of an empty message
                continue
            raw = plain[name] if name in plain else plain[name.rstrip("_")]  # keyword fields
            values[name] = self._value(kind.name, detail, raw)
        return self._store.types[type_name](**values)

    def _value(self, kind, detail, value):
        if kind == "NAME":
            return self._build(detail, value)
        if kind == "BASE":
            base = detail[0]
            if base in TEXT:
                return value
            if base == "char":
                return int(value) & 0xFF
            return bool(value) if base == "bool" else value
        (item_kind, item), _ = detail          # ARRAY or SEQUENCE
        if item_kind.name == "NAME":
            return [self._build(item, v) for v in value]
        base = item[0]
        if base in TEXT:
            return list(value)
        if isinstance(value, (bytes, bytearray)):
            array = np.frombuffer(bytes(value), dtype=np.uint8)
        else:
            array = np.asarray(value, dtype=np.int64 if base == "char" else DTYPES[base])
        if base == "char":
            array = array & 0xFF
        return array.astype(DTYPES[base])
