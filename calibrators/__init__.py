"""What is done with the virtual lab: agents act in it (``agents/``, planned on the
linearised model in ``planning/``), estimators fit their readings (``estimators/``, read
from files by ``measurements/``), studies compare strategies (``study/``), and the
real-machine workflow (``workflow/``) takes a builder from a plan to a compensated
controller; ``cli/`` is the ``orthoglide`` command over them."""
