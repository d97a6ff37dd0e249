"""``python -m naruto_agent.demo``: the main command (see :mod:`naruto_agent.demo`)."""

from naruto_agent.demo.run import main

if __name__ == "__main__":
    main()
