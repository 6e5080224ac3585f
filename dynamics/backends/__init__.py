"""The integrators behind the backend contract (`dynamics/backend.py`), each chosen only through its `REGISTRY`:
IDA (`ida`), IDA with numba-compiled callbacks through SUNDIALS' C interface (`ida_compiled`, `compiled_model`,
`native`, `sundials_c`) and diffrax (`diffrax_backend`, its compiled whole run `diffrax_run`, the vmapped batch
`diffrax_batch`).
"""
