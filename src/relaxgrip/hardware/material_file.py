"""Reading a material file (``relaxgrip fit-material --out``), checked."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from relaxgrip.errors import InputError
from relaxgrip.fileio import check_input_file
from relaxgrip.physics.material import Material

__all__ = ["load_material_file"]

_MAX_BYTES = 4 * 1024 * 1024


def load_material_file(path: str | Path) -> Material:
    """The :class:`~relaxgrip.physics.material.Material` in a JSON material file.

    Its provenance gains ``file`` and ``sha256`` (of the file read), so that a
    result of a twin built from it says which file that was.

    Raises
    ------
    relaxgrip.errors.InputError
        One line naming the file: missing, not JSON, not a material file, a
        newer schema, a bad field (:meth:`Material.from_dict`).
    """
    path = check_input_file(Path(path), "material file", InputError)
    data = path.read_bytes()
    if len(data) > _MAX_BYTES:
        raise InputError(f"{path}: larger than 4 MB, not a material file")
    try:
        obj = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: not a JSON material file ({exc})") from None
    material = Material.from_dict(obj, str(path))
    prov = material.provenance
    prov["file"] = path.name
    prov["sha256"] = hashlib.sha256(data).hexdigest()
    return Material(material.modulus, material.e_inf_pa, material.moduli_pa, material.tau_s,
                    material.shift, material.temp_range_c, json.dumps(prov, sort_keys=True))
