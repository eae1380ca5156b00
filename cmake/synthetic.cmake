# Component: synthetic (targets are added by the component's owner)
