import pytest

pytest.importorskip("distributed", reason="the fleet extra (dask[distributed]) is not installed")
pytest.importorskip("pyarrow", reason="the fleet extra (pyarrow) is not installed")
