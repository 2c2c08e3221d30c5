"""Payload-aware controllers: a design grid over a payload range, an on-line payload estimate.

:mod:`.grid` designs the controller file's recipe at every grid payload, :mod:`.bank`
identifies the payload with those designs' Kalman filters, and :mod:`.lqr_payload` and
:mod:`.mpc_payload` run the design at the estimate's light side.  An LQR or MPC file with a
``[payload]`` table (:class:`~flexctrl.spec.payload_settings.PayloadSettings`) builds them.
"""
