"""The observer's outputs over a logged run, as a file: ``uiogen validate OBSERVER --data LOG --out FILE``.

One sample per step of the run, on the log's own time base (the time column in s for a CSV or
Parquet log, the grid of an MDF log: :mod:`codegen.validation.logfiles`): every output of the
observer in the unit the model declares for it, and ``status``, the step's status flags (0: none).
The format is the name's: ``.mf4`` (or ``.mdf``) an MDF 4.10 file of one channel group (asammdf;
each channel's unit, the master ``time`` in s), ``.parquet`` (or ``.pq``) a Parquet table of
``time`` and the channels (each field's metadata ``unit``). Written chunk by chunk into a
temporary sibling that replaces ``FILE`` in one rename when the run and its checks have passed:
``FILE`` is the old file or the whole new one, never a part (a run refused half-way leaves
nothing).
"""
from __future__ import annotations

import contextlib
import os
from pathlib import Path

import numpy as np

from ..errors import ConfigurationError
from ..project import outputs

FORMATS = {".mf4": "mdf", ".mdf": "mdf", ".parquet": "parquet", ".pq": "parquet"}
STATUS = "status"


def check_path(path) -> str:
    """The format ``--out FILE`` asks for, by its suffix.

    Raises
    ------
    ConfigurationError
        another suffix (nothing is run).
    """
    fmt = FORMATS.get(Path(path).suffix.lower())
    if fmt is None:
        raise ConfigurationError(f"--out {path}: the file's suffix {Path(path).suffix or '(none)'!r} names no format "
                                 f"uiogen writes; allowed: {', '.join(FORMATS)} (MDF4 or Parquet)")
    return fmt


class OutputLog:
    """The outputs of a run, written chunk by chunk, put in place by :meth:`finish`.

    Parameters
    ----------
    path : str or os.PathLike
        ``.mf4``/``.mdf`` or ``.parquet``/``.pq``.
    units : mapping of str to str or None
        The observer's outputs in order, each with its unit (None: none declared).
    comment : str
        What the file holds (the observer and the log), kept in the file.
    """

    def __init__(self, path, units, comment: str):
        self.path, self.units, self.comment = Path(path), dict(units), comment
        self.format = check_path(path)
        if STATUS in self.units:        # an output named status would be hidden by the flags' channel
            raise ConfigurationError(f"--out {path}: the observer has an output named {STATUS!r}, the name of the "
                                     f"status channel; allowed: outputs with other names")
        outputs.make_folder(self.path.parent)
        # the suffix stays last: asammdf names an MDF file it saves by its suffix
        self.tmp = self.path.with_name(f".{self.path.stem}.tmp-{os.getpid()}{self.path.suffix}")
        self._writer = self._mdf = None

    def add(self, t: np.ndarray, out: np.ndarray, status: np.ndarray) -> None:
        """One chunk: times [s], outputs (n, n_outputs) in the order of ``units``, status flags (n,)."""
        with outputs.writing(self.path):
            if self.format == "parquet":
                self._parquet(t, out, status)
            else:
                self._mdf_chunk(t, out, status)

    def _parquet(self, t, out, status) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq
        fields = [pa.field("time", pa.float64(), metadata={"unit": "s"})]
        fields += [pa.field(n, pa.float64(), metadata={"unit": u} if u else None) for n, u in self.units.items()]
        fields.append(pa.field(STATUS, pa.int32()))
        schema = pa.schema(fields, metadata={"comment": self.comment})
        if self._writer is None:
            self._writer = pq.ParquetWriter(str(self.tmp), schema)
        arrays = [pa.array(np.asarray(t, float))] + [pa.array(out[:, j]) for j in range(out.shape[1])]
        arrays.append(pa.array(np.asarray(status, np.int32)))
        self._writer.write_table(pa.Table.from_arrays(arrays, schema=schema))

    def _mdf_chunk(self, t, out, status) -> None:
        from .logfiles import _mdf
        if self._mdf is None:
            from asammdf import Signal
            self._mdf = _mdf()(version="4.10")
            signals = [Signal(out[:, j], t, name=n, unit=u or "") for j, (n, u) in enumerate(self.units.items())]
            signals.append(Signal(np.asarray(status, np.int32), t, name=STATUS, unit=""))
            self._mdf.append(signals, comment=self.comment)
            return
        self._mdf.extend(0, [(np.asarray(t, float), None)] + [(out[:, j], None) for j in range(out.shape[1])]
                         + [(np.asarray(status, np.int32), None)])

    def finish(self) -> Path:
        """Close the temporary and put it in place (one rename); the path written."""
        try:
            with outputs.writing(self.path):
                if self._writer is not None:
                    self._writer.close()
                    self._writer = None
                if self._mdf is not None:
                    saved = self._mdf.save(self.tmp, overwrite=True)
                    self._mdf.close()
                    self._mdf = None
                    if Path(saved) != self.tmp:         # asammdf chose another name: never leave it behind
                        os.replace(saved, self.tmp)
                os.chmod(self.tmp, outputs.file_mode())
                os.replace(self.tmp, self.path)
        except BaseException:
            self.abort()
            raise
        return self.path

    def abort(self) -> None:
        """Drop the temporary (a run refused half-way writes nothing)."""
        with contextlib.suppress(Exception):
            if self._writer is not None:
                self._writer.close()
        with contextlib.suppress(Exception):
            if self._mdf is not None:
                self._mdf.close()
        self._writer = self._mdf = None
        with contextlib.suppress(OSError):
            self.tmp.unlink()
