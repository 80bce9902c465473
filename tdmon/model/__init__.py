"""Physics, pure numpy: survey, drill string, buoyancy, temperature, friction mu(T), torque and
drag, limits and broomsticks. Nothing here imports pydantic, asyncio or an I/O library."""
