"""The localization session: tracking, relocalization and odometry handling around a front-end
and a back-end (being split out of :mod:`fgloc.pipeline`)."""
